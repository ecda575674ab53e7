//! Where a match request's agents start: explicit poses (`robot_starts`, `opponent_starts`),
//! each a finite coordinate and no more of them than agents, else random points or the
//! map's spawns. Whether a pose is free space is the core's to check, against the map.

use lasertag_core::settings::FieldError;
use lasertag_core::world::Placement;

use crate::schema;

/// Refuses a coordinate that is not finite or lies far outside any map.
fn check_points<const N: usize>(field: &str, points: &[[f64; N]]) -> Result<(), FieldError> {
    for (i, p) in points.iter().enumerate() {
        if let Some(v) = p
            .iter()
            .find(|v| !v.is_finite() || v.abs() > schema::MAX_COORDINATE)
        {
            return Err(FieldError {
                field: format!("{field}[{i}]"),
                message: format!("{v} is not a finite coordinate"),
            });
        }
    }
    Ok(())
}

/// The placement of `agents` (robots, opponents): the starts given, or random points when
/// `random`, or the map's spawns. Fewer starts than agents is the core's to refuse (it
/// names the first agent without one); more would be silently left over.
pub fn placement(
    robot_starts: &[[f64; 3]],
    opponent_starts: &[[f64; 2]],
    (robots, opponents): (usize, usize),
    random: bool,
) -> Result<Placement, FieldError> {
    check_points("robot_starts", robot_starts)?;
    check_points("opponent_starts", opponent_starts)?;
    for (field, given, agents, what) in [
        ("robot_starts", robot_starts.len(), robots, "robots"),
        (
            "opponent_starts",
            opponent_starts.len(),
            opponents,
            "opponents",
        ),
    ] {
        if given > agents {
            return Err(FieldError {
                field: field.to_string(),
                message: format!("{given} starts for {agents} {what}: give one per agent"),
            });
        }
    }
    Ok(if !robot_starts.is_empty() || !opponent_starts.is_empty() {
        Placement::Given {
            robots: robot_starts
                .iter()
                .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
                .collect(),
            opponents: opponent_starts
                .iter()
                .map(|p| [p[0] as f32, p[1] as f32])
                .collect(),
        }
    } else if random {
        Placement::Random
    } else {
        Placement::Spawns
    })
}
