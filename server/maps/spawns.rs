//! Where robots and opponents start on an imported map, and where its landmarks stand:
//! chosen from the grid alone, deterministically, in free space with room for an agent.
//!
//! A cell is a possible spawn when a disc of [`SPAWN_CLEARANCE`] fits at its centre, so the
//! agent clears every wall by more than its radius (the validator's rule) and stands on a
//! cell the core's navigation calls passable. Only the largest connected region of such
//! cells is used, so everyone can reach everyone. Within it, distances are travel
//! distances (breadth-first over the cells): the robots start together at one end, the
//! opponents spread over the rest by farthest-point sampling (among cells about as far,
//! the roomier), as in the shipped maps, and the landmarks are spread the same way.

use lasertag_core::sim::AGENT_RADIUS;
use lasertag_core::sim::arena::NAV_MARGIN;

use crate::maps::format::Problem;
use crate::maps::grid::{Grid, round};

/// The room a spawn has around it (metres): an agent's radius, the core's navigation
/// margin and 2 cm to spare.
pub const SPAWN_CLEARANCE: f64 = (AGENT_RADIUS + NAV_MARGIN) as f64 + 0.02;

/// Robot spawns: matches have at most 8 robots and spawns wrap (a taken spawn moves the
/// next robot to the nearest free spot), so four, as in the shipped maps.
const ROBOTS: usize = 4;
/// Opponent spawns, spread over the map.
const OPPONENTS: usize = 8;
/// Robot spawns lie within this travel distance of the first (metres) and this far apart.
const TEAM_REACH: f64 = 3.0;
const TEAM_GAP: f64 = 1.0;
/// A further opponent spawn or landmark is placed only this far (travel) from the others.
const SPREAD_GAP: f64 = 2.0;
/// Among cells about as far away, spawns prefer room up to this much (metres), each metre
/// of it as good as `ROOM_WEIGHT` metres of travel.
const GOOD_ROOM: f64 = 1.0;
const ROOM_WEIGHT: f64 = 4.0;
/// A landmark for about every this many square metres of open floor, 4 to 16 of them.
const FLOOR_PER_LANDMARK: f64 = 50.0;

/// Spawns and landmarks, in map coordinates (metres).
#[derive(Debug, Clone, PartialEq)]
pub struct Placed {
    pub robots: Vec<[f64; 3]>,
    pub opponents: Vec<[f64; 2]>,
    pub landmarks: Vec<[f64; 2]>,
}

/// Most cells the search runs on: a bigger grid is searched coarsened (a cell a wall when
/// any cell it holds is, so every spawn found keeps its room on the fine grid). At 5 cm a
/// cell that is 51 m × 51 m; the search costs about 30 passes over its cells.
const MAX_SEARCH_CELLS: usize = 1 << 20;

/// Places spawns and landmarks on `grid`, or says why there is no room.
pub fn place(grid: &Grid) -> Result<Placed, Problem> {
    let cells = grid.cols * grid.rows;
    if cells <= MAX_SEARCH_CELLS {
        return place_on(grid);
    }
    let k = (cells as f64 / MAX_SEARCH_CELLS as f64).sqrt().ceil() as usize;
    place_on(&grid.clone().coarsen(k))
}

fn place_on(grid: &Grid) -> Result<Placed, Problem> {
    let n = grid.cols * grid.rows;
    let d2 = squared_distances(grid);
    let half_diagonal = std::f64::consts::FRAC_1_SQRT_2;
    // A lower bound of each cell centre's distance to the nearest wall (metres): the
    // nearest wall cell's centre is `sqrt(d2)` cells away and its square reaches at most
    // half a diagonal towards us.
    let room: Vec<f64> = d2
        .iter()
        .map(|&d| grid.cell * (f64::from(d).sqrt() - half_diagonal).max(0.0))
        .collect();
    let spawnable: Vec<bool> = (0..n)
        .map(|i| {
            if grid.blocked[i] {
                return false;
            }
            if room[i] >= SPAWN_CLEARANCE {
                return true;
            }
            // An upper bound: the nearest wall square reaches at least half a cell towards us.
            let most = grid.cell * (f64::from(d2[i]).sqrt() - 0.5);
            most >= SPAWN_CLEARANCE && exact_room_at_least(grid, i, SPAWN_CLEARANCE)
        })
        .collect();
    let region = largest_region(grid, &spawnable).ok_or_else(|| {
        Problem::Content(format!(
            "no free space wide enough for an agent: a spawn needs {SPAWN_CLEARANCE} m from \
             every wall (unknown counts as wall)"
        ))
    })?;
    let inside: Vec<bool> = {
        let mut v = vec![false; n];
        for &i in &region {
            v[i] = true;
        }
        v
    };
    let centre = |i: usize| {
        let (c, r) = (i % grid.cols, i / grid.cols);
        [(c as f64 + 0.5) * grid.cell, (r as f64 + 0.5) * grid.cell]
    };
    let metres = |d: u32| d as f64 * grid.cell;
    let apart = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);

    // Far first, roomy among the far: one metre of room weighs as much as a few of travel.
    let score = |dist: &[u32], i: usize| metres(dist[i]) + ROOM_WEIGHT * room[i].min(GOOD_ROOM);
    // The roomiest cell, then the cell farthest from it: one end of the region.
    let roomiest = argmax(&region, |i| room[i]).unwrap_or(region[0]);
    let mut dist = vec![u32::MAX; n];
    bfs(grid, &inside, &mut dist, roomiest);
    let first = argmax(&region, |i| score(&dist, i)).unwrap_or(roomiest);

    // The first opponent spawn: the cell farthest from the first robot spawn.
    dist.fill(u32::MAX);
    let order = bfs(grid, &inside, &mut dist, first);
    let far = argmax(&region, |i| score(&dist, i)).unwrap_or(first);
    if apart(centre(far), centre(first)) < 2.0 * SPAWN_CLEARANCE {
        return Err(Problem::Content(format!(
            "the largest connected free space with room for an agent is {:.1} m², too small \
             for a robot and an opponent to start apart (is it broken up by unknown or noisy \
             cells?)",
            region.len() as f64 * grid.cell * grid.cell
        )));
    }
    let mut from_far = vec![u32::MAX; n];
    bfs(grid, &inside, &mut from_far, far);

    // The robots: the first spawn and the nearest cells around it, a little apart, on its
    // side of the map.
    let mut robots: Vec<usize> = vec![first];
    for &i in &order {
        if robots.len() == ROBOTS || metres(dist[i]) > TEAM_REACH {
            break;
        }
        if dist[i] < from_far[i]
            && robots
                .iter()
                .all(|&j| apart(centre(i), centre(j)) >= TEAM_GAP)
        {
            robots.push(i);
        }
    }
    for &r in &robots[1..] {
        bfs(grid, &inside, &mut dist, r);
    }

    // The opponents: that first one, then each the cell farthest from every spawn so far.
    let mut opponents: Vec<usize> = vec![far];
    bfs(grid, &inside, &mut dist, far);
    while opponents.len() < OPPONENTS {
        let Some(next) = argmax(&region, |i| score(&dist, i)) else {
            break;
        };
        if metres(dist[next]) < SPREAD_GAP {
            break;
        }
        opponents.push(next);
        bfs(grid, &inside, &mut dist, next);
    }

    // The landmarks: spread over the whole region, starting far from the robots.
    let floor = region.len() as f64 * grid.cell * grid.cell;
    let count = (floor / FLOOR_PER_LANDMARK).round().clamp(4.0, 16.0) as usize;
    dist.fill(u32::MAX);
    for &r in &robots {
        bfs(grid, &inside, &mut dist, r);
    }
    let mut landmarks: Vec<usize> = Vec::new();
    while landmarks.len() < count {
        let Some(far) = argmax(&region, |i| dist[i] as f64) else {
            break;
        };
        if metres(dist[far]) < SPREAD_GAP {
            break;
        }
        landmarks.push(far);
        bfs(grid, &inside, &mut dist, far);
    }

    let (mid_x, mid_y) = (
        grid.cols as f64 * grid.cell / 2.0,
        grid.rows as f64 * grid.cell / 2.0,
    );
    let point = |i: usize| centre(i).map(round);
    Ok(Placed {
        robots: robots
            .iter()
            .map(|&i| {
                let [x, y] = centre(i);
                // Facing the middle of the arena, as opponents do when they join.
                let heading = if (mid_x - x).abs() + (mid_y - y).abs() < 1e-9 {
                    0.0
                } else {
                    (mid_y - y).atan2(mid_x - x)
                };
                [round(x), round(y), round(heading)]
            })
            .collect(),
        opponents: opponents.iter().map(|&i| point(i)).collect(),
        landmarks: landmarks.iter().map(|&i| point(i)).collect(),
    })
}

/// The cell of `cells` with the largest `key`, the first on ties.
fn argmax(cells: &[usize], key: impl Fn(usize) -> f64) -> Option<usize> {
    let mut best: Option<(f64, usize)> = None;
    for &i in cells {
        let k = key(i);
        if best.is_none_or(|(b, _)| k > b) {
            best = Some((k, i));
        }
    }
    best.map(|(_, i)| i)
}

/// Whether the disc of radius `need` around cell `i`'s centre meets no wall cell and stays
/// inside the grid: exact, looking at the cells around it.
fn exact_room_at_least(grid: &Grid, i: usize, need: f64) -> bool {
    let reach = (need / grid.cell + 0.5).ceil() as isize + 1;
    let (c, r) = ((i % grid.cols) as isize, (i / grid.cols) as isize);
    for dr in -reach..=reach {
        for dc in -reach..=reach {
            let (cc, rr) = (c + dc, r + dr);
            let outside = cc < 0 || rr < 0 || cc >= grid.cols as isize || rr >= grid.rows as isize;
            if !outside && !grid.is_blocked(cc as usize, rr as usize) {
                continue;
            }
            let gap = |d: isize| (d.abs() as f64 - 0.5).max(0.0);
            if grid.cell * gap(dc).hypot(gap(dr)) < need {
                return false;
            }
        }
    }
    true
}

/// For every cell, the squared distance (in cells) from its centre to the nearest wall
/// cell's centre, the cells just outside the grid counting as wall (the arena's border):
/// Felzenszwalb and Huttenlocher's exact transform, a column pass then a row pass.
fn squared_distances(grid: &Grid) -> Vec<u32> {
    // The grid with a ring of wall around it; `NONE` marks a free cell before the passes.
    let (w, h) = (grid.cols + 2, grid.rows + 2);
    let mut f: Vec<u32> = vec![0; w * h];
    for r in 0..grid.rows {
        for c in 0..grid.cols {
            if !grid.is_blocked(c, r) {
                f[(r + 1) * w + c + 1] = NONE;
            }
        }
    }
    let mut column = vec![NONE; h];
    let mut out = vec![0; h];
    for c in 0..w {
        for r in 0..h {
            column[r] = f[r * w + c];
        }
        lower_envelope(&column, &mut out);
        for r in 0..h {
            f[r * w + c] = out[r];
        }
    }
    let mut out = vec![0; w];
    let mut d2 = vec![0; grid.cols * grid.rows];
    for r in 1..h - 1 {
        lower_envelope(&f[r * w..(r + 1) * w], &mut out);
        d2[(r - 1) * grid.cols..r * grid.cols].copy_from_slice(&out[1..w - 1]);
    }
    d2
}

/// No value yet, in [`squared_distances`]. Real values stay far below it: a grid is at most
/// 4096 cells a side, so a squared distance is at most 2 × 4098².
const NONE: u32 = u32::MAX;

/// One dimension of the transform: `out[q] = min over p of (q - p)² + f[p]`, over the sites
/// `p` that have a value. Every column and row of the ringed grid has one.
fn lower_envelope(f: &[u32], out: &mut [u32]) {
    let mut sites: Vec<usize> = Vec::new();
    // Where each site's parabola starts being the lowest.
    let mut starts: Vec<f64> = Vec::new();
    let value = |p: usize| f64::from(f[p]) + (p * p) as f64;
    for (q, &site) in f.iter().enumerate() {
        if site == NONE {
            continue;
        }
        loop {
            let Some(&p) = sites.last() else {
                sites.push(q);
                starts.push(f64::NEG_INFINITY);
                break;
            };
            let s = (value(q) - value(p)) / (2.0 * (q - p) as f64);
            if starts.last().is_some_and(|&z| s <= z) {
                sites.pop();
                starts.pop();
                continue;
            }
            sites.push(q);
            starts.push(s);
            break;
        }
    }
    let mut k = 0;
    for (q, slot) in out.iter_mut().enumerate() {
        if sites.is_empty() {
            *slot = NONE;
            continue;
        }
        while k + 1 < sites.len() && starts[k + 1] < q as f64 {
            k += 1;
        }
        let p = sites[k];
        let d = q.abs_diff(p) as u64;
        *slot = u32::try_from(d * d + u64::from(f[p])).unwrap_or(NONE);
    }
}

/// The cells of the largest 4-connected region of `open` cells (the first found on ties),
/// in index order; `None` when there is no open cell.
fn largest_region(grid: &Grid, open: &[bool]) -> Option<Vec<usize>> {
    let mut seen = vec![false; open.len()];
    let mut best: Option<Vec<usize>> = None;
    for start in 0..open.len() {
        if !open[start] || seen[start] {
            continue;
        }
        seen[start] = true;
        let mut region = vec![start];
        let mut head = 0;
        while head < region.len() {
            let i = region[head];
            head += 1;
            for j in neighbours(grid, i) {
                if open[j] && !seen[j] {
                    seen[j] = true;
                    region.push(j);
                }
            }
        }
        if best.as_ref().is_none_or(|b| region.len() > b.len()) {
            best = Some(region);
        }
    }
    best.map(|mut b| {
        b.sort_unstable();
        b
    })
}

/// The 4-neighbours of cell `i` inside the grid.
fn neighbours(grid: &Grid, i: usize) -> impl Iterator<Item = usize> {
    let (c, r, cols, rows) = (i % grid.cols, i / grid.cols, grid.cols, grid.rows);
    [
        (c > 0).then(|| i - 1),
        (c + 1 < cols).then(|| i + 1),
        (r > 0).then(|| i - cols),
        (r + 1 < rows).then(|| i + cols),
    ]
    .into_iter()
    .flatten()
}

/// Breadth-first travel distances (in cells) from `source` over the `inside` cells, lowering
/// `dist` where the source is nearer than what it holds (so that repeated calls give the
/// distance to the nearest of several sources). Returns the cells it reached, nearest first.
fn bfs(grid: &Grid, inside: &[bool], dist: &mut [u32], source: usize) -> Vec<usize> {
    if dist[source] == 0 {
        return Vec::new();
    }
    dist[source] = 0;
    let mut queue = vec![source];
    let mut head = 0;
    while head < queue.len() {
        let i = queue[head];
        head += 1;
        for j in neighbours(grid, i) {
            if inside[j] && dist[j] > dist[i] + 1 {
                dist[j] = dist[i] + 1;
                queue.push(j);
            }
        }
    }
    queue
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::maps::grid::Grid;

    fn grid(rows: &[&str], cell: f64) -> Grid {
        let cols = rows[0].len();
        let mut g = Grid::free(cols, rows.len(), cell);
        for (i, line) in rows.iter().enumerate() {
            for (c, ch) in line.chars().enumerate() {
                g.set(c, rows.len() - 1 - i, ch == '#');
            }
        }
        g
    }

    #[test]
    fn the_distance_transform_is_exact() {
        let g = grid(&["#......", ".......", "...#..."], 1.0);
        let d2 = squared_distances(&g);
        for r in 0..g.rows {
            for c in 0..g.cols {
                // Brute force over the wall cells and the ring outside the grid.
                let mut best = u32::MAX;
                for rr in -1..=g.rows as i64 {
                    for cc in -1..=g.cols as i64 {
                        let outside =
                            rr < 0 || cc < 0 || rr >= g.rows as i64 || cc >= g.cols as i64;
                        if outside || g.is_blocked(cc as usize, rr as usize) {
                            let (dc, dr) = (cc - c as i64, rr - r as i64);
                            best = best.min((dc * dc + dr * dr) as u32);
                        }
                    }
                }
                assert_eq!(d2[r * g.cols + c], best, "cell ({c}, {r})");
            }
        }
    }

    #[test]
    fn spawns_keep_their_room_and_the_teams_start_apart() {
        let g = grid(
            &[
                "##########################",
                "#........................#",
                "#........................#",
                "#........................#",
                "#..........####..........#",
                "#........................#",
                "#........................#",
                "#........................#",
                "##########################",
            ],
            0.5,
        );
        let placed = place(&g).unwrap();
        let clear = |x: f64, y: f64| {
            let (c, r) = ((x / 0.5) as usize, (y / 0.5) as usize);
            exact_room_at_least(&g, r * g.cols + c, SPAWN_CLEARANCE)
        };
        assert!(placed.robots.iter().all(|s| clear(s[0], s[1])));
        assert!(placed.opponents.iter().all(|s| clear(s[0], s[1])));
        assert!(!placed.robots.is_empty() && !placed.opponents.is_empty());
        assert!(placed.landmarks.len() >= 2);
        let (r, o) = (placed.robots[0], placed.opponents[0]);
        assert!((r[0] - o[0]).abs() > 5.0, "{placed:?}");
        // The same grid, the same spawns.
        assert_eq!(place(&g).unwrap(), placed);
    }

    #[test]
    fn a_corridor_one_metre_wide_has_room_for_spawns() {
        let g = grid(&["#########", "#.......#", "#########"], 1.0);
        let placed = place(&g).unwrap();
        assert!(placed.robots.iter().all(|s| s[1] == 1.5));
        // The robots at one end, the first opponent at the other.
        assert_eq!(placed.robots[0][0], 7.5, "{placed:?}");
        assert_eq!(placed.opponents[0][0], 1.5, "{placed:?}");
    }

    #[test]
    fn no_room_is_an_error() {
        let g = grid(&["###", "#.#", "###"], 0.5);
        let e = place(&g).unwrap_err().to_string();
        assert!(e.contains("no free space wide enough"), "{e}");
    }
}
