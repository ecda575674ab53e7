// Compact snapshots (`?format=compact`): the binary form of a `snapshot` message, decoded
// into the same object the JSON form gives, so the rest of the page does not know which it
// got. The layout is in server/protocol/compact.rs and docs/api.md. Scans and localisation
// clouds come only every few ticks: between them each robot keeps its last ones. A delta
// (kind 2) patches a whole snapshot the page holds (the one it names) into the next one; a
// motion part (kind 3, over WebTransport: the whole of that tick follows) is shown and kept
// as no baseline.

const TURN = (Math.PI * 2) / 65536;
const CONTROL = ["bot", "api", "human"];
const STATE = ["valid", "suspicious", "invalid"];
const utf8 = new TextDecoder();
/** How far behind the newest a kept baseline may be (ticks): what an acknowledgement names. */
const HELD = 32;

export class CompactDecoder {
  constructor() {
    this.slow = new Map(); // robot id -> {scan, cloud} from the last snapshot that had them
    this.held = new Map(); // tick -> whole snapshot (Uint8Array): what a delta may be against
    this.newest = null; // the newest tick held
  }

  /** Which snapshots the page holds, for an acknowledgement (docs/api.md, "WebTransport"):
   * the newest tick and, in bit i, whether it holds tick newest - 1 - i. */
  acks() {
    if (this.newest === null) return null;
    let bits = 0;
    for (let i = 0; i < 32; i++) if (this.held.has(this.newest - 1 - i)) bits |= 1 << i;
    return { newest: this.newest, bits: bits >>> 0 };
  }

  /** Keeps `bytes` (a whole snapshot of `tick`) as a baseline: the newest 33 ticks, the
   * rest dropped; a tick far behind the newest (time went back) starts over. */
  keep(tick, bytes) {
    if (this.newest !== null && tick + HELD < this.newest) this.held.clear();
    this.held.set(tick, bytes);
    if (this.newest === null || tick > this.newest || this.held.size === 1) this.newest = tick;
    for (const t of this.held.keys()) if (t + HELD < this.newest) this.held.delete(t);
  }

  /** The whole snapshot a delta message stands for (see `apply_delta` in compact.rs). */
  undelta(bytes) {
    const d = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    const base = this.held.get(d.getUint32(6, true));
    if (!base) throw new Error("a delta against a snapshot this page does not hold");
    const out = base.slice();
    let at = 0;
    for (let i = 10; i < bytes.length; ) {
      at += bytes[i];
      const n = bytes[i + 1];
      i += 2;
      if (i + n > bytes.length || at + n > out.length) throw new Error("a delta past its end");
      out.set(bytes.subarray(i, i + n), at);
      at += n;
      i += n;
    }
    return out;
  }

  /** Decodes one binary message (an ArrayBuffer) into a snapshot object. */
  decode(message) {
    let bytes = new Uint8Array(message);
    const motion = bytes[0] === 3;
    if (bytes[0] === 2) bytes = this.undelta(bytes);
    const buffer = bytes.buffer;
    const d = new DataView(buffer);
    if (!motion) this.keep(d.getUint32(2, true), bytes);
    let at = 0;
    const u8 = () => d.getUint8(at++);
    const u16 = () => { const v = d.getUint16(at, true); at += 2; return v; };
    const u32 = () => { const v = d.getUint32(at, true); at += 4; return v; };
    const m = () => u16() / 100;
    const angle = () => { const a = u16() * TURN; return a > Math.PI ? a - Math.PI * 2 : a; };
    const pose = () => ({ x: m(), y: m(), theta: angle() });
    if (u8() !== 1 && !motion) throw new Error("not a compact snapshot");
    const flags = u8();
    const spectator = (flags & 1) !== 0, hasBelief = (flags & 2) !== 0, youRobot = (flags & 64) !== 0;
    const tick = u32();
    const timeLeft = u16() / 10;
    const ack = u32();
    const you = u8();
    const score = { tags: u8(), robot_tags: u16(), opponents: u8(), opponents_left: u8(), robots_frozen: u8() };
    const robots = [];
    for (let n = u8(); n > 0; n--) {
      const id = `r${u8()}`;
      const p = pose();
      const bits = u8();
      const r = { id, ...p, frozen: (bits & 1) !== 0 };
      if (bits & 2) r.goal = pose();
      if (bits & 4) { r.estimate = pose(); r.spread = u16() / 1000; }
      if (bits & 8) {
        const cloud = [];
        for (let k = u8(); k > 0; k--) cloud.push(u16(), u16());
        const scan = [];
        for (let k = u8(); k > 0; k--) scan.push(Math.round((u8() * 100) / 32));
        this.slow.set(id, { cloud, scan });
      }
      if (bits & 16) {
        const len = u8();
        r.name = utf8.decode(new Uint8Array(buffer, at, len));
        at += len;
      }
      // A spectator's robots, and a person's own robot, keep their last scan between slow parts.
      const kept = (spectator || (youRobot && id === `r${you - 1}`)) && this.slow.get(id);
      if (kept) { r.cloud = kept.cloud; r.scan = kept.scan; }
      robots.push(r);
    }
    const opponents = [];
    for (let n = u8(); n > 0; n--) {
      const index = u8();
      const p = pose();
      const bits = u8();
      // An anonymous sighting (a person on the robot team's view): where, not who or which way.
      if (bits & 32) { opponents.push({ id: "o?", x: p.x, y: p.y, tagged: (bits & 1) !== 0 }); continue; }
      const id = `o${index}`;
      const o = { id, ...p, tagged: (bits & 1) !== 0, control: CONTROL[(bits >> 1) & 3] || "bot" };
      if (bits & 8) {
        const len = u8();
        o.name = utf8.decode(new Uint8Array(buffer, at, len));
        at += len;
      }
      opponents.push(o);
    }
    let belief;
    if (hasBelief) {
      belief = { tick: u32(), roles: [] };
      const cell = u8();
      for (let n = u8(); n > 0; n--) {
        const role = { id: u32(), count: u8() };
        const bits = u8();
        role.tagged = (bits & 1) !== 0;
        role.state = STATE[(bits >> 1) & 3] || "invalid";
        role.confidence = Math.round((u8() / 255) * 100) / 100;
        role.particles = u32();
        role.mean = [m(), m()];
        // Cells `cell` cm wide, as Rice-coded gaps in raster order from the cloud's lowest
        // x and y (server/protocol/compact/cells.rs): each point back in centimetres.
        const points = [];
        const count = u16();
        if (count > 0) {
          const x0 = u16(), y0 = u16(), columns = u16() + 1, k = u8();
          const from = at;
          let bit = 0;
          const read = () => { const b = (d.getUint8(from + (bit >> 3)) >> (7 - (bit & 7))) & 1; bit++; return b; };
          let sum = 0;
          for (let i = 0; i < count; i++) {
            let gap = 0;
            while (read()) gap++;
            // Doubled, not shifted: a gap may pass the 32 bits JavaScript's shifts keep.
            for (let j = 0; j < k; j++) gap = gap * 2 + read();
            sum += gap;
            points.push(x0 + (sum % columns) * cell, y0 + Math.floor(sum / columns) * cell);
          }
          at = from + Math.ceil(bit / 8);
        }
        role.points = points;
        belief.roles.push(role);
      }
    }
    const winner = flags & 16 ? "robots" : flags & 32 ? "opponents" : null;
    const s = {
      type: "snapshot", tick, time_left_s: timeLeft, status: flags & 8 ? "finished" : "running", winner,
      view: spectator ? "spectator" : flags & 128 ? "teammates" : "player", you: you ? `${youRobot ? "r" : "o"}${you - 1}` : null, robots, opponents, score,
    };
    if (!spectator) s.ack = ack;
    if (belief) s.belief = belief;
    return s;
  }
}
