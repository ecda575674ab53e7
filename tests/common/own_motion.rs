//! What the measurement programs in `examples/` share about a player's own motion in the
//! page: a hook that times each W/S key press to the first animation frame in which the
//! player's own disc has moved (its latencies in `window.__ownMotion.lat`, milliseconds),
//! and the percentile their tables print.

/// The page-side hook: install it once the player's view is up (`Browser::eval`).
pub const HOOK: &str = r#"(() => {
  const p = window.__ownMotion = { lat: [], waiting: false };
  addEventListener("keydown", (e) => {
    if ((e.code === "KeyW" || e.code === "KeyS") && !e.repeat) {
      const o = window.__lasertag.own;
      p.t0 = performance.now(); p.start = o ? { x: o.x, y: o.y } : null; p.waiting = true;
    }
  }, true);
  const loop = () => requestAnimationFrame(() => {
    const o = window.__lasertag.own;
    if (p.waiting && o && p.start && Math.hypot(o.x - p.start.x, o.y - p.start.y) > 0.001) {
      p.lat.push(performance.now() - p.t0);
      p.waiting = false;
    }
    loop();
  });
  loop();
  return true;
})()"#;

/// The `q` quantile of `v` (nearest rank; NaN for none).
pub fn percentile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}
