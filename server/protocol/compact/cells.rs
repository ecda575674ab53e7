//! A belief role's points as quantised cells, as the compact snapshot carries them
//! (docs/api.md, "Compact snapshots").
//!
//! The points are particles the page draws as squares 7 cm wide (at least 2.5 px): at whole
//! centimetres, 4 bytes a point, they would be most of a spectator's bytes. Here each point is
//! rounded to a cell `cell` centimetres wide on a grid whose corner is the cloud's lowest
//! x and y, and the cells are listed in raster order as gaps from one to the next, each in a
//! Golomb-Rice code (`k` chosen for the role): a cloud of a few hundred points takes about
//! 1.2 bytes a point, a cloud spread over the whole map included, where a byte-aligned varint
//! takes 2 for most of its gaps. Sorting does not change the picture (a role's squares are
//! one colour at one opacity, and painting them in any order gives the same pixels), and a
//! point whose cell is already listed comes again as a gap of 0, so the page draws as many
//! squares as before, each at most half a cell from where the centimetres put it.
//!
//! ```text
//! u16 points | [points > 0: u16 x0 | u16 y0 (cm) | u16 columns - 1 | u8 k | gaps, bits]
//! ```
//!
//! A gap `g` is `g >> k` one bits and a zero bit, then its low `k` bits, most significant
//! first; bits fill each byte from its top bit, the last byte padded with zeros. A point is
//! at `x0 + (s % columns) × cell`, `y0 + (s / columns) × cell`, `s` the sum of the gaps so
//! far.

/// Why a cloud of cells could not be read.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CellsError {
    #[error("the cloud runs past the end of the message")]
    Overrun,
    #[error("a gap longer than a grid of u16 columns and rows holds")]
    GapTooLong,
}

/// The largest Rice parameter: a gap within a grid of 65,536 × 65,536 cells is under 2^32.
const MAX_K: u8 = 32;

/// Appends `points` (centimetres, at most `u16::MAX` of them; each coordinate clamped to a
/// `u16`) as cells `cell` centimetres wide (at least 1).
pub fn encode(out: &mut Vec<u8>, points: &[[i32; 2]], cell: u16) {
    let points = &points[..points.len().min(u16::MAX as usize)];
    out.extend_from_slice(&(points.len() as u16).to_le_bytes());
    let clamp = |v: i32| v.clamp(0, u16::MAX as i32) as u32;
    let (Some(x0), Some(y0)) = (
        points.iter().map(|p| clamp(p[0])).min(),
        points.iter().map(|p| clamp(p[1])).min(),
    ) else {
        return;
    };
    let cell = u32::from(cell.max(1));
    // Rounded to the nearest cell: at most half a cell off.
    let at = |v: i32, origin: u32| (clamp(v) - origin + cell / 2) / cell;
    let columns = points.iter().map(|p| at(p[0], x0)).max().unwrap_or(0) + 1;
    let mut keys: Vec<u64> = points
        .iter()
        .map(|p| u64::from(at(p[1], y0)) * u64::from(columns) + u64::from(at(p[0], x0)))
        .collect();
    keys.sort_unstable();
    let mut last = 0;
    let gaps: Vec<u64> = keys
        .into_iter()
        .map(|key| {
            let g = key - last;
            last = key;
            g
        })
        .collect();
    out.extend_from_slice(&(x0 as u16).to_le_bytes());
    out.extend_from_slice(&(y0 as u16).to_le_bytes());
    // The last column's index: a grid of 1 cm cells over the whole u16 range has 65,536.
    out.extend_from_slice(&((columns - 1) as u16).to_le_bytes());
    let k = best_k(&gaps);
    out.push(k);
    let mut bits = Bits { out, free: 0 };
    for g in gaps {
        for _ in 0..g >> k {
            bits.push(true);
        }
        bits.push(false);
        for i in (0..k).rev() {
            bits.push((g >> i) & 1 == 1);
        }
    }
}

/// The Rice parameter that codes `gaps` in the fewest bits.
fn best_k(gaps: &[u64]) -> u8 {
    (0..=MAX_K)
        .min_by_key(|k| {
            gaps.iter()
                .map(|g| (g >> k) + 1 + u64::from(*k))
                .sum::<u64>()
        })
        .unwrap_or(0)
}

/// Bits appended to a message, each byte filled from its top bit.
struct Bits<'a> {
    out: &'a mut Vec<u8>,
    /// Bits of the last byte not yet written.
    free: u8,
}

impl Bits<'_> {
    fn push(&mut self, bit: bool) {
        if self.free == 0 {
            self.out.push(0);
            self.free = 8;
        }
        self.free -= 1;
        if bit && let Some(last) = self.out.last_mut() {
            *last |= 1 << self.free;
        }
    }
}

/// The points `bytes` starts with (cells `cell` centimetres wide, as [`encode`] wrote
/// them), in centimetres and in raster order, and how many bytes they took: what a client
/// does (the page's copy is in `web/compact.js`).
pub fn decode(bytes: &[u8], cell: u16) -> Result<(Vec<[u32; 2]>, usize), CellsError> {
    let u16_at = |i: usize| {
        bytes
            .get(i..i + 2)
            .map(|b| u32::from(u16::from_le_bytes([b[0], b[1]])))
            .ok_or(CellsError::Overrun)
    };
    let n = u16_at(0)? as usize;
    if n == 0 {
        return Ok((Vec::new(), 2));
    }
    let (x0, y0, columns) = (u16_at(2)?, u16_at(4)?, u64::from(u16_at(6)?) + 1);
    let k = *bytes.get(8).ok_or(CellsError::Overrun)?;
    if k > MAX_K {
        return Err(CellsError::GapTooLong);
    }
    let cell = u64::from(cell.max(1));
    let start = 9;
    let mut bit = 0usize;
    let mut read = || {
        let byte = bytes.get(start + bit / 8).ok_or(CellsError::Overrun)?;
        let b = (byte >> (7 - bit % 8)) & 1;
        bit += 1;
        Ok::<u64, CellsError>(u64::from(b))
    };
    let mut sum = 0u64;
    let mut points = Vec::with_capacity(n);
    for _ in 0..n {
        let mut quotient = 0u64;
        while read()? == 1 {
            quotient += 1;
            if quotient << k > 1 << 33 {
                return Err(CellsError::GapTooLong);
            }
        }
        let mut low = 0u64;
        for _ in 0..k {
            low = (low << 1) | read()?;
        }
        sum += (quotient << k) | low;
        if sum / columns > u64::from(u16::MAX) {
            return Err(CellsError::GapTooLong);
        }
        let x = u64::from(x0) + (sum % columns) * cell;
        let y = u64::from(y0) + (sum / columns) * cell;
        points.push([x as u32, y as u32]);
    }
    Ok((points, start + bit.div_ceil(8)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sorted(mut v: Vec<[u32; 2]>) -> Vec<[u32; 2]> {
        v.sort_unstable();
        v
    }

    #[test]
    fn points_come_back_within_half_a_cell_and_as_many() {
        // A cloud of a few hundred points over 3 m, some of them in one cell.
        let mut points: Vec<[i32; 2]> = (0..300)
            .map(|i| [1200 + (i * 37) % 300, 800 + (i * 91) % 250])
            .collect();
        points.extend([[1201, 801], [1202, 802], [1200, 800]]);
        let mut out = vec![0xaa];
        encode(&mut out, &points, 4);
        let (back, len) = decode(&out[1..], 4).expect("decodes");
        assert_eq!(len, out.len() - 1);
        assert_eq!(back.len(), points.len());
        // Each point, rounded to its cell, is one of those decoded (as many times).
        let rounded = |v: i32, origin: i32| origin + (v - origin + 2) / 4 * 4;
        let want = sorted(
            points
                .iter()
                .map(|p| [rounded(p[0], 1200) as u32, rounded(p[1], 800) as u32])
                .collect(),
        );
        assert_eq!(sorted(back), want);
        // Well under the 4 bytes a point of two centimetre u16s takes.
        assert!(len < 9 + 2 * points.len(), "{len} bytes");
    }

    #[test]
    fn every_point_is_within_half_a_cell_of_its_cell() {
        let points = [
            [0, 0],
            [3, 5],
            [65_535, 40_000],
            [-10, 70_000],
            [1999, 2001],
        ];
        let mut out = Vec::new();
        encode(&mut out, &points, 5);
        let (back, _) = decode(&out, 5).expect("decodes");
        let clamp = |v: i32| v.clamp(0, u16::MAX as i32) as u32;
        for p in points.iter().map(|p| [clamp(p[0]), clamp(p[1])]) {
            assert!(
                back.iter()
                    .any(|q| p[0].abs_diff(q[0]) <= 2 && p[1].abs_diff(q[1]) <= 2),
                "{p:?} not within half a cell of any of {back:?}"
            );
        }
        assert_eq!(back.len(), points.len());
    }

    #[test]
    fn a_grid_of_1_cm_cells_spans_the_whole_u16_range() {
        let points = [[0, 0], [65_535, 65_535], [65_535, 0]];
        let mut out = Vec::new();
        encode(&mut out, &points, 1);
        let (back, _) = decode(&out, 1).expect("decodes");
        assert_eq!(back, [[0, 0], [65_535, 0], [65_535, 65_535]]);
    }

    #[test]
    fn no_points_and_broken_clouds() {
        let mut out = Vec::new();
        encode(&mut out, &[], 4);
        assert_eq!(out, [0, 0]);
        assert_eq!(decode(&out, 4), Ok((Vec::new(), 2)));
        encode(&mut out, &[[100, 100], [900, 900]], 4);
        let cloud = &out[2..];
        assert_eq!(
            decode(&cloud[..cloud.len() - 1], 4),
            Err(CellsError::Overrun)
        );
        // One point, 2 columns, k = 32: a gap of 2^32 cells, past 65,536 rows.
        let huge = [1, 0, 0, 0, 0, 0, 1, 0, 32, 0b1000_0000, 0, 0, 0, 0];
        assert_eq!(decode(&huge, 4), Err(CellsError::GapTooLong));
        assert_eq!(
            decode(&[1, 0, 0, 0, 0, 0, 1, 0, 33, 0], 4),
            Err(CellsError::GapTooLong)
        );
    }
}
