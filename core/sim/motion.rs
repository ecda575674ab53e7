//! Kinematics and collisions of disc agents.
//!
//! Each tick an agent's [`Motion`] proposes a new pose ([`propose`]); [`resolve`] then slides
//! the disc out of walls and other agents. A proposed step is at most a few centimetres, far
//! less than the disc radius, so pushing the centre out along the contact normal can never
//! tunnel through a wall; if a position still overlaps after a few passes (a tight corner
//! between agents) the agent simply keeps its old position, which was free.

use nalgebra::{Point2, Vector2};

use crate::sim::arena::Arena;
use crate::sim::{AGENT_RADIUS, DT, Motion, Pose, wrap_angle};

/// The pose `motion` would reach in one tick, ignoring collisions.
pub fn propose(pose: Pose, motion: Motion, speed: f32, turn_rate: f32) -> Pose {
    match motion {
        Motion::Stop => pose,
        Motion::Drive { forward, turn } => {
            let forward = finite_or_zero(forward).clamp(-1.0, 1.0);
            let turn = finite_or_zero(turn).clamp(-1.0, 1.0);
            let theta = wrap_angle(pose.theta + turn * turn_rate * DT);
            // Move along the mean heading of the tick: the exact arc for small turns.
            let mid = pose.theta + 0.5 * turn * turn_rate * DT;
            let step = forward * speed * DT;
            Pose {
                pos: pose.pos + Vector2::new(mid.cos(), mid.sin()) * step,
                theta,
            }
        }
        Motion::Toward(target) => {
            let d = target - pose.pos;
            let dist = d.norm();
            if dist < 1e-5 {
                return pose;
            }
            let step = dist.min(speed * DT);
            let want = d.y.atan2(d.x);
            let err = wrap_angle(want - pose.theta);
            let max_turn = turn_rate * DT;
            Pose {
                pos: pose.pos + d / dist * step,
                theta: wrap_angle(pose.theta + err.clamp(-max_turn, max_turn)),
            }
        }
    }
}

fn finite_or_zero(v: f32) -> f32 {
    if v.is_finite() { v } else { 0.0 }
}

/// Where a disc that wants to go from `old` to `proposed` ends up, given the walls and the
/// centres of the other (active) agents. Never returns a position overlapping either.
pub fn resolve(
    arena: &Arena,
    old: Point2<f32>,
    proposed: Point2<f32>,
    others: &[Point2<f32>],
) -> Point2<f32> {
    const PASSES: usize = 4;
    const SKIN: f32 = 1e-4;
    let mut p = proposed;
    for _ in 0..PASSES {
        let mut moved = false;
        if !arena.surely_clear(p, AGENT_RADIUS) {
            let q = arena.closest_wall_point(p);
            let d = (p - q).norm();
            if d < AGENT_RADIUS {
                if d < 1e-6 || arena.inside_obstacle(p) {
                    return old;
                }
                p = q + (p - q) / d * (AGENT_RADIUS + SKIN);
                moved = true;
            }
        }
        for o in others {
            let v = p - o;
            let d = v.norm();
            if d < 2.0 * AGENT_RADIUS {
                if d < 1e-6 {
                    return old;
                }
                p = o + v / d * (2.0 * AGENT_RADIUS + SKIN);
                moved = true;
            }
        }
        if !moved {
            return p;
        }
    }
    let free = arena.disc_is_free(p, AGENT_RADIUS)
        && others.iter().all(|o| (p - o).norm() >= 2.0 * AGENT_RADIUS);
    if free { p } else { old }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::arena::MapDef;

    fn open() -> Arena {
        Arena::new(MapDef {
            name: "open".into(),
            width: 5.0,
            height: 5.0,
            obstacles: vec![],
            robot_spawns: vec![[1.0, 1.0, 0.0]],
            opponent_spawns: vec![Point2::new(4.0, 4.0)],
            landmarks: vec![],
        })
    }

    #[test]
    fn drive_respects_top_speed_and_turn_rate() {
        let p = propose(
            Pose::new(1.0, 1.0, 0.0),
            Motion::Drive {
                forward: 5.0,
                turn: 0.0,
            },
            1.0,
            2.0,
        );
        assert!((p.pos.x - 1.05).abs() < 1e-5);
        let p = propose(
            Pose::new(1.0, 1.0, 0.0),
            Motion::Drive {
                forward: 0.0,
                turn: -1.0,
            },
            1.0,
            2.0,
        );
        assert!((p.theta + 0.1).abs() < 1e-5);
        let p = propose(
            Pose::new(1.0, 1.0, 0.0),
            Motion::Drive {
                forward: f32::NAN,
                turn: 0.0,
            },
            1.0,
            2.0,
        );
        assert_eq!(p.pos, Point2::new(1.0, 1.0));
    }

    #[test]
    fn a_disc_slides_along_a_wall_and_never_overlaps_it() {
        let a = open();
        let mut p = Point2::new(1.0, 0.3);
        for _ in 0..100 {
            // Push diagonally into the bottom wall: x advances, y stays out of the wall.
            let target = p + Vector2::new(0.03, -0.03);
            p = resolve(&a, p, target, &[]);
            assert!(a.clearance(p) >= AGENT_RADIUS - 1e-4, "{p:?}");
        }
        assert!(p.x > 2.5, "slid along: {p:?}");
    }

    #[test]
    fn discs_do_not_overlap_each_other() {
        let a = open();
        let other = Point2::new(2.0, 2.0);
        let mut p = Point2::new(1.0, 2.0);
        for _ in 0..100 {
            p = resolve(&a, p, p + Vector2::new(0.05, 0.0), &[other]);
            assert!((p - other).norm() >= 2.0 * AGENT_RADIUS - 1e-4);
        }
    }
}
