//! MovingAI benchmark grids (`.map`, Sturtevant's pathfinding benchmarks): a header
//! (`type octile`, `height H`, `width W`, `map`), then H rows of W terrain characters.
//!
//! Passable: `.` and `G` (ground) and `S` (swamp, which the benchmarks let a unit enter from
//! ground). Blocked: `@` and `O` (out of bounds), `T` (trees) and `W` (water, which cannot be
//! entered from ground). Our maps have one kind of wall, which stops robots and lasers
//! alike, so water is a wall; a swamp is floor. The first row is the top of the map (as the
//! benchmarks draw it), so a map reads the same way up in our viewer.

use crate::maps::format::{MAX_CELLS, Problem};
use crate::maps::grid::Grid;

/// The terrain characters and what they are.
const TERRAIN: &str = ". G S @ O T W";

/// Whether a terrain character is a wall, or `None` when it is not a terrain character.
pub fn is_wall(ch: u8) -> Option<bool> {
    match ch {
        b'.' | b'G' | b'S' => Some(false),
        b'@' | b'O' | b'T' | b'W' => Some(true),
        _ => None,
    }
}

/// Parses a MovingAI grid whose cells are `cell` metres square.
pub fn parse(bytes: &[u8], cell: f64) -> Result<Grid, Problem> {
    let text =
        std::str::from_utf8(bytes).map_err(|e| Problem::Content(format!("not UTF-8 text: {e}")))?;
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim_end()));
    let (mut kind, mut height, mut width) = (None, None, None);
    let mut last_line = 0;
    loop {
        let Some((line, l)) = lines.next() else {
            return Err(Problem::line(
                last_line,
                "the file ends before the `map` line that starts the grid",
            ));
        };
        last_line = line;
        let mut words = l.split_whitespace();
        let (key, value) = (words.next(), words.next());
        match (key, value) {
            (Some("map"), None) => break,
            (Some("type"), Some(v)) => kind = Some((line, v.to_string())),
            (Some(k @ ("height" | "width")), Some(v)) => {
                let n = v.parse::<usize>().ok().filter(|&n| n > 0 && n <= MAX_CELLS);
                let Some(n) = n else {
                    return Err(Problem::line(
                        line,
                        format!("{k}: expected a whole number from 1 to {MAX_CELLS}, found {v:?}"),
                    ));
                };
                if k == "height" {
                    height = Some(n);
                } else {
                    width = Some(n);
                }
            }
            (None, _) => {}
            _ => {
                return Err(Problem::line(
                    line,
                    format!(
                        "expected `type octile`, `height H`, `width W` or `map`, found {:?}",
                        l.chars().take(40).collect::<String>()
                    ),
                ));
            }
        }
    }
    match kind {
        Some((_, k)) if k == "octile" => {}
        Some((line, k)) => {
            return Err(Problem::line(
                line,
                format!("type: {k:?}; only `type octile` grids are read"),
            ));
        }
        None => {
            return Err(Problem::field(
                "type",
                "the header has no `type octile` line",
            ));
        }
    }
    let (Some(height), Some(width)) = (height, width) else {
        return Err(Problem::field(
            if height.is_none() { "height" } else { "width" },
            "missing from the header",
        ));
    };
    if width.saturating_mul(height) > MAX_CELLS {
        return Err(Problem::Content(format!(
            "the grid is {width} × {height} cells, the limit is {MAX_CELLS}"
        )));
    }
    let mut grid = Grid::free(width, height, cell);
    for row in 0..height {
        let Some((line, l)) = lines.next() else {
            return Err(Problem::line(
                last_line + 1,
                format!("the grid has {row} rows, the header says height {height}"),
            ));
        };
        last_line = line;
        if l.len() != width {
            return Err(Problem::line(
                line,
                format!(
                    "the row has {} characters, the header says width {width}",
                    l.len()
                ),
            ));
        }
        for (col, ch) in l.bytes().enumerate() {
            let Some(wall) = is_wall(ch) else {
                let shown = l.get(col..).and_then(|s| s.chars().next()).unwrap_or('?');
                return Err(Problem::line(
                    line,
                    format!(
                        "column {}: {shown:?} is not a terrain character ({TERRAIN})",
                        col + 1
                    ),
                ));
            };
            grid.set(col, height - 1 - row, wall);
        }
    }
    if let Some((line, _)) = lines.find(|(_, l)| !l.is_empty()) {
        return Err(Problem::line(
            line,
            format!("more rows than the header's height {height}"),
        ));
    }
    Ok(grid)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn terrain_becomes_walls_with_the_first_row_on_top() {
        let text = "type octile\r\nheight 2\r\nwidth 4\r\nmap\r\n.GS@\r\nOTW.\r\n";
        let g = parse(text.as_bytes(), 0.5).unwrap();
        assert_eq!((g.cols, g.rows, g.cell), (4, 2, 0.5));
        // Row 0 is the bottom: the file's last row.
        assert_eq!(
            g.blocked,
            vec![true, true, true, false, false, false, false, true]
        );
    }

    #[test]
    fn malformed_files_name_the_line() {
        let cases = [
            (
                "type octile\nheight 2\nwidth 2\n",
                "line 3: the file ends before the `map`",
            ),
            (
                "type hex\nheight 1\nwidth 1\nmap\n.\n",
                "line 1: type: \"hex\"",
            ),
            (
                "height 1\nwidth 1\nmap\n.\n",
                "type: the header has no `type octile`",
            ),
            ("type octile\nwidth 1\nmap\n.\n", "height: missing"),
            (
                "type octile\nheight x\nwidth 1\nmap\n",
                "line 2: height: expected a whole number",
            ),
            ("type octile\nheight 0\nwidth 1\nmap\n", "line 2: height"),
            (
                "type octile\ncolour red\nmap\n",
                "line 2: expected `type octile`",
            ),
            (
                "type octile\nheight 2\nwidth 2\nmap\n..\n",
                "line 6: the grid has 1 rows",
            ),
            (
                "type octile\nheight 1\nwidth 2\nmap\n...\n",
                "line 5: the row has 3 characters",
            ),
            (
                "type octile\nheight 1\nwidth 2\nmap\n.X\n",
                "line 5: column 2: 'X'",
            ),
            (
                "type octile\nheight 1\nwidth 2\nmap\n..\n@@\n",
                "line 6: more rows",
            ),
            (
                "type octile\nheight 5000\nwidth 5000\nmap\n",
                "the limit is",
            ),
        ];
        for (text, want) in cases {
            let e = parse(text.as_bytes(), 1.0).unwrap_err().to_string();
            assert!(e.contains(want), "{e:?} lacks {want:?}");
        }
        assert!(parse(&[0xff, 0xfe], 1.0).is_err());
    }
}
