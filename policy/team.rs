//! A policy driving a match's robots: each robot's observation vector (the research
//! environment's one layout, `lasertag_core::env::Layout`) through the model, its action read
//! as the environments read one (`lasertag_core::env::drive_order`), every `every` ticks.
//!
//! With [`TeamPolicy::unparked`] (the shipped models), a robot the policy leaves standing
//! still is walked on by [`crate::unpark`]: the project's team never waits out a person who
//! hides.
//!
//! The shell (the server's match task, the native engine, the experiments) applies the orders
//! as inputs, so they go into the match's record like any robot command: a replay or a
//! resumed match never needs the model again to reproduce what happened.

use std::sync::Arc;

use lasertag_core::env::{Layout, drive_order};
use lasertag_core::sim::Physics;
use lasertag_core::sim::arena::Arena;
use lasertag_core::world::{RobotOrder, World};

use crate::unpark::{Decision, Unpark};
use crate::{Policy, PolicyError};

/// Ticks between two decisions of a served policy: ten a second. The shipped team was trained
/// at five (the environment's default `ticks_per_step`), but a turn held for 0.2 s swings a
/// robot well past its ±5° tag cone; held half as long, the same model tags a robot it sees
/// sooner (docs/research.md, "Measured with the capture experiment").
pub const DEFAULT_EVERY: u64 = 2;

/// The most ticks between two decisions an uploaded policy may ask for (`?decide_every=`):
/// one a second. A policy trained at the environment's `ticks_per_step` k plays as trained
/// served every k ticks.
pub const MAX_EVERY: u64 = 20;

/// Values of an action a policy must give (forward, turn, tag).
pub const ACTION_SIZE: usize = lasertag_core::env::ACTION_SIZE;

/// A policy set up for one match: its layout and the buffers one decision uses.
#[derive(Debug, Clone)]
pub struct TeamPolicy {
    policy: Arc<Policy>,
    layout: Layout,
    every: u64,
    observation: Vec<f32>,
    action: Vec<f32>,
    scratch: Vec<f32>,
    /// Each robot's guard against parking, for a shipped team ([`TeamPolicy::unparked`]).
    unpark: Option<Vec<Unpark>>,
}

/// The detection slots a model of `input_len` values has in a team of `robots` on a match
/// with `physics`' sensors, or why it cannot drive such a team.
pub fn detection_slots(
    input_len: usize,
    robots: usize,
    physics: &Physics,
) -> Result<usize, PolicyError> {
    let base = layout(robots, 0, 1.0, 1.0, physics).size();
    let per = 3;
    if input_len < base || !(input_len - base).is_multiple_of(per) {
        return Err(PolicyError::Shape(format!(
            "the model takes {input_len} values; a robot of a team of {robots} observes {base} + 3 per detection slot (docs/research.md, \"Observations\"): it was trained for another team size"
        )));
    }
    Ok((input_len - base) / per)
}

/// Whether `policy` can drive a team of `robots` on a match with `physics`' sensors: its
/// action is a robot's and its input a robot's observation. Its detection slots if so.
pub fn fits(policy: &Policy, robots: usize, physics: &Physics) -> Result<usize, PolicyError> {
    check_action(policy)?;
    detection_slots(policy.input_len(), robots, physics)
}

/// Whether `policy` gives a robot's action (forward, turn, tag).
pub fn check_action(policy: &Policy) -> Result<(), PolicyError> {
    if policy.output_len() != ACTION_SIZE {
        return Err(PolicyError::Shape(format!(
            "the model gives {} values; a robot's action is {ACTION_SIZE} (forward, turn, tag)",
            policy.output_len()
        )));
    }
    Ok(())
}

fn layout(robots: usize, detections: usize, width: f64, height: f64, physics: &Physics) -> Layout {
    // The rules as `GET /api/rules` publishes them (to the micrometre), which the HTTP
    // environment reads: the same divisors give the same vector.
    let exact = |v: f32| ((v as f64) * 1e6).round() / 1e6;
    Layout::new(
        robots,
        detections,
        width,
        height,
        physics.laser_beams,
        exact(physics.laser_range),
        exact(physics.laser_fov.to_degrees()),
    )
}

impl TeamPolicy {
    /// `policy` for a team of `robots` on `arena` with `physics`' sensors, deciding every
    /// `every` ticks (at least 1). Refused when the model's sizes do not fit the team.
    pub fn new(
        policy: Arc<Policy>,
        arena: &Arena,
        robots: usize,
        physics: &Physics,
        every: u64,
    ) -> Result<TeamPolicy, PolicyError> {
        let detections = fits(&policy, robots, physics)?;
        // The map's size to the millimetre, as the API writes it.
        let mm = |v: f32| ((v as f64) * 1000.0).round() / 1000.0;
        let layout = layout(
            robots,
            detections,
            mm(arena.width()),
            mm(arena.height()),
            physics,
        );
        Ok(TeamPolicy {
            observation: vec![0.0; layout.size()],
            layout,
            policy,
            every: every.max(1),
            action: Vec::with_capacity(ACTION_SIZE),
            scratch: Vec::new(),
            unpark: None,
        })
    }

    /// This team with the guard against parking ([`crate::unpark`]): what the project
    /// serves its own shipped models with. An uploaded model drives as it was trained, so
    /// a researcher measures their policy, not the guard.
    pub fn unparked(mut self) -> TeamPolicy {
        self.unpark = Some(Vec::new());
        self
    }

    /// Ticks between decisions.
    pub fn every(&self) -> u64 {
        self.every
    }

    /// The orders of this tick (none between decisions): one for every robot driven from
    /// outside that no person holds, from what that robot knows now (none for a robot
    /// walking on from where it stood).
    pub fn orders(&mut self, world: &World) -> Vec<(usize, RobotOrder)> {
        if !world.tick.is_multiple_of(self.every) {
            return Vec::new();
        }
        let limit = world.config.time_limit_ticks.max(1) as f64;
        let time_fraction = (world.tick as f64 / limit).min(1.0);
        let mut orders = Vec::new();
        if let Some(guards) = self.unpark.as_mut() {
            guards.resize(world.robots.len(), Unpark::default());
        }
        for i in 0..world.robots.len() {
            let guard = self.unpark.as_mut().and_then(|g| g.get_mut(i));
            if !world.robot_outside(i) || world.robots[i].seated {
                if let Some(guard) = guard {
                    *guard = Unpark::default();
                }
                continue;
            }
            match guard.map_or(Decision::Policy, |g| g.decide(world, i)) {
                Decision::Policy => {}
                Decision::Walking => continue,
                Decision::Start(order) => {
                    orders.push((i, order));
                    continue;
                }
            }
            let Some(o) = world.observation(i) else {
                continue;
            };
            self.layout
                .encode(&o, i, time_fraction, &mut self.observation);
            // The sizes were checked when the team was set up: this cannot fail.
            if self
                .policy
                .infer(&self.observation, &mut self.action, &mut self.scratch)
                .is_ok()
            {
                orders.push((i, drive_order(&self.action)));
            }
        }
        orders
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Limits;
    use crate::testing::model;
    use crate::unpark::UNPARK_AFTER_TICKS;
    use lasertag_core::bots::BotKind;
    use lasertag_core::planner::PlannerKind;
    use lasertag_core::sim::arena::MapDef;
    use lasertag_core::sim::still::LongestStill;
    use lasertag_core::world::{MatchConfig, MatchStatus, WorldInput};
    use nalgebra::Point2;

    #[test]
    fn a_policy_that_stands_still_is_walked_on_before_a_person_would_call_it_parked() {
        // Two rooms joined by a door; the opponent stands in the far one, out of sight.
        let arena = Arc::new(Arena::new(MapDef {
            name: "rooms".into(),
            width: 16.0,
            height: 8.0,
            obstacles: vec![vec![
                Point2::new(8.0, 0.0),
                Point2::new(8.2, 0.0),
                Point2::new(8.2, 6.0),
                Point2::new(8.0, 6.0),
            ]],
            robot_spawns: vec![[1.0, 1.0, 0.0], [1.0, 3.0, 0.0]],
            opponent_spawns: vec![Point2::new(14.0, 1.0)],
            landmarks: vec![],
        }));
        let config = MatchConfig {
            robots: 2,
            opponents: 1,
            opponent_bot: BotKind::Idle,
            planner: PlannerKind::Api,
            time_limit_ticks: 60 * 20,
            ..MatchConfig::default()
        };
        let mut world = World::new(arena.clone(), config).expect("a world");
        let physics = world.config.physics.clone();
        // A model whose every action is 0: forward 0, turn 0, no tag. It stands forever.
        let inputs = layout(2, 0, 16.0, 8.0, &physics).size();
        let stand = model(
            inputs,
            &[(vec![vec![0.0; inputs]; 3], vec![0.0; 3], "Identity")],
        );
        let policy = Arc::new(Policy::from_onnx(&stand, &Limits::default()).expect("a model"));
        let mut team = TeamPolicy::new(policy.clone(), &arena, 2, &physics, DEFAULT_EVERY)
            .expect("fits")
            .unparked();
        let mut still = LongestStill::default();
        let mut walks = 0;
        while world.status == MatchStatus::Running && world.tick < 40 * 20 {
            for (robot, order) in team.orders(&world) {
                walks += matches!(order, RobotOrder::Waypoints(_)) as usize;
                world
                    .apply(&WorldInput::Robot { robot, order })
                    .expect("the order is taken");
            }
            world.step();
            for (i, r) in world.robots.iter().enumerate() {
                still.push(i, r.pose.pos, world.tick);
            }
        }
        assert!(walks >= 2, "both robots were walked on: {walks} walks");
        // An uploaded model drives as trained: without the guard nobody is walked.
        let mut world = World::new(arena.clone(), world.config.clone()).expect("a world");
        let mut plain = TeamPolicy::new(policy, &arena, 2, &physics, DEFAULT_EVERY).expect("fits");
        for _ in 0..300 {
            assert!(
                plain
                    .orders(&world)
                    .iter()
                    .all(|(_, o)| !matches!(o, RobotOrder::Waypoints(_)))
            );
            world.step();
        }
        assert!(
            still.longest_ticks() < 2 * UNPARK_AFTER_TICKS,
            "no robot stood 10 s: the longest stood {} ticks",
            still.longest_ticks()
        );
    }
}
