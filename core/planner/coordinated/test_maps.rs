//! Maps the unit tests of scoring and passages share.

use std::sync::Arc;

use nalgebra::Point2;

use crate::sim::arena::{Arena, MapDef};

/// Two 6 m × 6 m rooms joined by a corridor 4 m long and 0.9 m wide: too narrow for two
/// robots to pass each other. The opponent is walled into a pocket in a corner, out of
/// sight, so that nothing distracts the robots.
pub(super) fn corridor() -> Arc<Arena> {
    Arc::new(Arena::new(MapDef {
        name: "corridor".into(),
        width: 16.0,
        height: 6.0,
        obstacles: vec![
            vec![
                Point2::new(6.0, 0.0),
                Point2::new(10.0, 0.0),
                Point2::new(10.0, 2.55),
                Point2::new(6.0, 2.55),
            ],
            vec![
                Point2::new(6.0, 3.45),
                Point2::new(10.0, 3.45),
                Point2::new(10.0, 6.0),
                Point2::new(6.0, 6.0),
            ],
            vec![
                Point2::new(0.0, 4.5),
                Point2::new(2.0, 4.5),
                Point2::new(2.0, 4.6),
                Point2::new(0.0, 4.6),
            ],
            vec![
                Point2::new(1.9, 4.6),
                Point2::new(2.0, 4.6),
                Point2::new(2.0, 6.0),
                Point2::new(1.9, 6.0),
            ],
        ],
        robot_spawns: vec![[2.0, 3.0, 0.0]],
        opponent_spawns: vec![Point2::new(0.9, 5.3)],
        landmarks: vec![],
    }))
}
