//! Where agents start: the map's spawns in order, explicit starts checked for room, or
//! random free points that all reach each other (seeded).

use super::*;

/// Start poses for every robot and opponent (see [`Placement`]).
pub(super) fn place_agents(
    arena: &Arena,
    config: &MatchConfig,
    rng: &mut ChaCha8Rng,
) -> Result<(Vec<Pose>, Vec<Pose>), SetupError> {
    let def = &arena.def;
    let mut taken: Vec<Point2<f32>> = Vec::new();
    let mut robots = Vec::with_capacity(config.robots);
    let mut opponents = Vec::with_capacity(config.opponents);
    let random_cells: Vec<usize> = if config.placement == Placement::Random {
        reachable_cells(arena)
    } else {
        Vec::new()
    };
    let mut pick_random = |taken: &[Point2<f32>], id: String| -> Result<Point2<f32>, SetupError> {
        for _ in 0..10_000 {
            let Some(&cell) = random_cells.get(rng.random_range(0..random_cells.len().max(1)))
            else {
                break;
            };
            let p = arena.grid.centre(cell);
            if taken.iter().all(|t| (t - p).norm() >= 1.0) {
                return Ok(p);
            }
        }
        Err(SetupError::NoRoom(id))
    };
    for i in 0..config.robots {
        let id = AgentId::Robot(i).to_string();
        let (pos, theta) = match &config.placement {
            Placement::Random => {
                let p = pick_random(&taken, id)?;
                (p, 0.0)
            }
            Placement::Given { robots: given, .. } if !given.is_empty() => {
                let s = given.get(i).ok_or_else(|| SetupError::BadStart {
                    field: "robot_starts".into(),
                    message: format!(
                        "has {} entries, the match has {} robots",
                        given.len(),
                        config.robots
                    ),
                })?;
                let p = Point2::new(s[0], s[1]);
                check_given(arena, &taken, p, format!("robot_starts[{i}]"))?;
                (p, s[2])
            }
            _ => {
                let s = def.robot_spawns[i % def.robot_spawns.len()];
                (
                    free_near(arena, &taken, Point2::new(s[0], s[1]))
                        .ok_or(SetupError::NoRoom(id))?,
                    s[2],
                )
            }
        };
        taken.push(pos);
        robots.push(Pose { pos, theta });
    }
    for i in 0..config.opponents {
        let id = AgentId::Opponent(i).to_string();
        let pos = match &config.placement {
            Placement::Random => pick_random(&taken, id)?,
            Placement::Given {
                opponents: given, ..
            } if !given.is_empty() => {
                let s = given.get(i).ok_or_else(|| SetupError::BadStart {
                    field: "opponent_starts".into(),
                    message: format!(
                        "has {} entries, the match has {} opponents",
                        given.len(),
                        config.opponents
                    ),
                })?;
                let p = Point2::new(s[0], s[1]);
                check_given(arena, &taken, p, format!("opponent_starts[{i}]"))?;
                p
            }
            _ => {
                let s = def.opponent_spawns[i % def.opponent_spawns.len()];
                free_near(arena, &taken, s).ok_or(SetupError::NoRoom(id))?
            }
        };
        taken.push(pos);
        // Face the middle of the arena: a sensible default for a person who just joined.
        let centre = Point2::new(arena.width() / 2.0, arena.height() / 2.0) - pos;
        opponents.push(Pose {
            pos,
            theta: centre.y.atan2(centre.x),
        });
    }
    Ok((robots, opponents))
}

pub(super) fn check_given(
    arena: &Arena,
    taken: &[Point2<f32>],
    p: Point2<f32>,
    field: String,
) -> Result<(), SetupError> {
    if !(p.x.is_finite() && p.y.is_finite() && arena.disc_is_free(p, AGENT_RADIUS)) {
        return Err(SetupError::BadStart {
            field,
            message: format!("[{}, {}] is not free space for an agent", p.x, p.y),
        });
    }
    if taken.iter().any(|t| (t - p).norm() < 2.0 * AGENT_RADIUS) {
        return Err(SetupError::BadStart {
            field,
            message: format!("[{}, {}] overlaps another agent", p.x, p.y),
        });
    }
    Ok(())
}

/// `want` itself when free of walls and agents, else the nearest passable cell that is.
pub(super) fn free_near(
    arena: &Arena,
    taken: &[Point2<f32>],
    want: Point2<f32>,
) -> Option<Point2<f32>> {
    let clear = |p: Point2<f32>| {
        taken
            .iter()
            .all(|t| (t - p).norm() >= 2.0 * AGENT_RADIUS + 0.05)
    };
    if arena.disc_is_free(want, AGENT_RADIUS) && clear(want) {
        return Some(want);
    }
    let g = &arena.grid;
    let mut cells: Vec<(f32, usize)> = (0..g.len())
        .filter(|&c| g.passable(c))
        .map(|c| ((g.centre(c) - want).norm_squared(), c))
        .filter(|(d, _)| *d < 25.0)
        .collect();
    cells.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    cells
        .into_iter()
        .map(|(_, c)| g.centre(c))
        .find(|p| clear(*p))
}

/// Passable cells reachable from the first robot spawn (so random starts can meet).
pub(super) fn reachable_cells(arena: &Arena) -> Vec<usize> {
    let s = arena.def.robot_spawns[0];
    match crate::nav::DistanceField::from_point(&arena.grid, Point2::new(s[0], s[1])) {
        Some(f) => (0..arena.grid.len()).filter(|&c| f.reachable(c)).collect(),
        None => Vec::new(),
    }
}
