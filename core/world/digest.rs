//! A digest of the whole state of a match (FNV-1a over every number that matters), so
//! that tests can check that the same seed and inputs give the same match, tick for tick.

use super::*;

impl World {
    /// A digest of the whole observable state, for determinism tests.
    pub fn digest(&self) -> u64 {
        let mut h = Fnv::default();
        h.write(self.tick);
        h.write(self.status as u64);
        for r in &self.robots {
            h.pose(r.pose);
            h.write(r.frozen_until);
            h.write(r.cooldown_until);
            r.scan
                .ranges
                .iter()
                .for_each(|v| h.write(v.to_bits() as u64));
            for d in &r.scan.detections {
                h.write(d.range.to_bits() as u64);
                h.write(d.bearing.to_bits() as u64);
            }
            if let Some(g) = r.command.goal {
                h.pose(g);
            }
        }
        for o in &self.opponents {
            h.pose(o.pose);
            h.write(o.tagged as u64);
        }
        h.write(self.events.len() as u64);
        h.0
    }
}

#[derive(Debug)]
struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv {
    fn write(&mut self, v: u64) {
        for b in v.to_le_bytes() {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }

    fn pose(&mut self, p: Pose) {
        self.write(p.pos.x.to_bits() as u64);
        self.write(p.pos.y.to_bits() as u64);
        self.write(p.theta.to_bits() as u64);
    }
}
