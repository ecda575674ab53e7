//! Teams driven by a shipped trained policy (`policy:<name>`, `lasertag_policy`) in the
//! experiments: before each tick the policy's orders go in as inputs, every
//! [`DEFAULT_EVERY`] ticks, as the server's match task and the Python package's native
//! engine give them, so a study measures the team people play against.

use std::sync::Arc;

use lasertag_core::world::{World, WorldInput};
use lasertag_policy::team::DEFAULT_EVERY;
use lasertag_policy::{Limits, Policy, SHIPPED, TeamPolicy};

use crate::error::LabError;
use crate::part::Params;

/// How a planner list names a policy: `policy:<name>`.
pub const PREFIX: &str = "policy:";

/// The shipped policies as a planner list names them, comma-separated.
pub fn shipped_names() -> String {
    let names: Vec<String> = SHIPPED
        .iter()
        .map(|(name, _)| format!("{PREFIX}{name}"))
        .collect();
    names.join(", ")
}

/// Whether `name` is a shipped policy's.
pub fn is_shipped(name: &str) -> bool {
    lasertag_policy::shipped(name).is_some()
}

/// The shipped policy `name`, read and checked.
pub fn load(name: &str) -> Result<Arc<Policy>, LabError> {
    let bytes = lasertag_policy::shipped(name).ok_or_else(|| {
        LabError::Arguments(format!(
            "{PREFIX}{name}: no shipped policy of that name (the experiments run the shipped \
             ones: {})",
            shipped_names()
        ))
    })?;
    let policy =
        Policy::from_onnx(bytes, &Limits::default()).map_err(|error| LabError::Policy {
            name: name.to_string(),
            error,
        })?;
    Ok(Arc::new(policy))
}

/// A fingerprint of the shipped policy `name`'s model (FNV-1a, 64 bits, over its bytes), so
/// that parts of a study run with different models do not merge.
pub fn fingerprint(name: &str) -> String {
    let bytes = lasertag_policy::shipped(name).unwrap_or_default();
    let hash = bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    });
    format!("fnv1a64:{hash:016x}")
}

/// `policy.<name>` (its model's fingerprint) for each policy a study runs, once each.
pub fn to_params<'a>(names: impl IntoIterator<Item = &'a str>, params: &mut Params) {
    let mut seen: Vec<&str> = Vec::new();
    for name in names {
        if !seen.contains(&name) {
            params.set(format!("policy.{name}"), fingerprint(name));
            seen.push(name);
        }
    }
}

/// The policy the match of `world` names (`MatchConfig::policy`) set up to drive its team,
/// or `None` when it names none.
pub fn for_world(world: &World) -> Result<Option<TeamPolicy>, LabError> {
    let Some(name) = world.config.policy.as_deref() else {
        return Ok(None);
    };
    let team = TeamPolicy::new(
        load(name)?,
        &world.arena,
        world.robots.len(),
        &world.config.physics,
        DEFAULT_EVERY,
    )
    .map_err(|error| LabError::Policy {
        name: name.to_string(),
        error,
    })?;
    // The experiments run the shipped models, served with their guard against parking.
    Ok(Some(team.unparked()))
}

/// One tick of `world`: the policy's orders of this tick first, when a policy drives.
pub fn step(team: Option<&mut TeamPolicy>, world: &mut World) {
    if let Some(team) = team {
        for (robot, order) in team.orders(world) {
            // An action read as the environments read it (clipped) is always taken.
            let _ = world.apply(&WorldInput::Robot { robot, order });
        }
    }
    world.step();
}

#[cfg(test)]
mod tests {
    use super::*;
    use lasertag_core::difficulty::Difficulty;
    use lasertag_core::sim::arena::{Arena, MapDef};
    use lasertag_core::world::MatchConfig;
    use nalgebra::Point2;

    fn world(seed: u64) -> World {
        let arena = Arc::new(Arena::new(MapDef {
            name: "room".into(),
            width: 10.0,
            height: 6.0,
            obstacles: vec![],
            robot_spawns: vec![[1.0, 1.0, 0.0], [1.0, 2.0, 0.0]],
            opponent_spawns: vec![Point2::new(8.0, 4.0)],
            landmarks: vec![],
        }));
        let mut config = MatchConfig {
            opponents: 1,
            seed,
            ..MatchConfig::default()
        };
        Difficulty::Learned.apply(&mut config);
        World::new(arena, config).unwrap()
    }

    #[test]
    fn the_learned_preset_is_driven_by_its_shipped_policy_the_same_way_each_time() {
        let run = |seed| {
            let mut w = world(seed);
            let mut team = for_world(&w).unwrap().expect("the preset names a policy");
            for _ in 0..60 {
                step(Some(&mut team), &mut w);
            }
            w.digest()
        };
        assert_eq!(run(4), run(4));
        let mut idle = world(4);
        (0..60).for_each(|_| step(None, &mut idle));
        assert_ne!(run(4), idle.digest(), "the policy's robots moved");
    }

    #[test]
    fn an_unknown_policy_names_the_shipped_ones() {
        let e = load("nope").unwrap_err().to_string();
        assert!(
            e.contains("policy:nope") && e.contains("policy:learned"),
            "{e}"
        );
        assert!(is_shipped("learned") && !is_shipped("nope"));
    }
}
