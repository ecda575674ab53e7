//! What a robot knows of its teammates when it plans: read directly with a perfect radio,
//! as last heard otherwise.

use nalgebra::Point2;

use super::{Coordinated, ahead};
use crate::planner::view::{Knowledge, TeamView};

/// What a robot knows of a teammate when it plans (see [`Knowledge`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Mate {
    pub(super) index: usize,
    pub(super) pos: Point2<f32>,
    pub(super) frozen: bool,
    pub(super) pursuing: bool,
    /// Where it is going.
    pub(super) goal: Option<Point2<f32>>,
    /// It still follows a path.
    pub(super) moving: bool,
    pub(super) making_way: bool,
}

impl Coordinated {
    /// Teammates as robot `i` knows them, in index order: read directly with shared memory,
    /// as last heard otherwise (a teammate never heard from is unknown and left out).
    pub(super) fn mates(&self, know: &Knowledge, view: &TeamView, i: usize) -> Vec<Mate> {
        (0..view.robots.len())
            .filter(|&j| j != i)
            .filter_map(|j| {
                if know.shared_memory() {
                    let r = &self.robots[j];
                    let outside = view.robots[j].outside && self.settings.outside_claims;
                    Some(Mate {
                        index: j,
                        pos: view.robots[j].pose.pos,
                        frozen: view.robots[j].frozen,
                        pursuing: r.seeing || outside,
                        goal: if outside {
                            Some(ahead(view.robots[j].pose).pos)
                        } else {
                            self.goal_pose(j).map(|g| g.pos)
                        },
                        moving: !r.path.finished(),
                        making_way: r.making_way.is_some(),
                    })
                } else {
                    know.heard(i, j).map(|m| Mate {
                        index: j,
                        pos: m.pose.pos,
                        frozen: m.frozen,
                        pursuing: m.status.pursuing,
                        goal: m.status.goal.map(|g| g.pos),
                        moving: !m.status.route.is_empty(),
                        making_way: m.status.making_way,
                    })
                }
            })
            .collect()
    }
}
