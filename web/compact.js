// Compact snapshots (`?format=compact`): the binary form of a `snapshot` message, decoded
// into the same object the JSON form gives, so the rest of the page does not know which it
// got. The layout is in server/protocol/compact.rs and docs/api.md. Scans and localisation
// clouds come only every few ticks: between them each robot keeps its last ones.

const TURN = (Math.PI * 2) / 65536;
const CONTROL = ["bot", "api", "human"];
const STATE = ["valid", "suspicious", "invalid"];
const utf8 = new TextDecoder();

export class CompactDecoder {
  constructor() {
    this.slow = new Map(); // robot id -> {scan, cloud} from the last snapshot that had them
  }

  /** Decodes one binary message (an ArrayBuffer) into a snapshot object. */
  decode(buffer) {
    const d = new DataView(buffer);
    let at = 0;
    const u8 = () => d.getUint8(at++);
    const u16 = () => { const v = d.getUint16(at, true); at += 2; return v; };
    const u32 = () => { const v = d.getUint32(at, true); at += 4; return v; };
    const m = () => u16() / 100;
    const angle = () => { const a = u16() * TURN; return a > Math.PI ? a - Math.PI * 2 : a; };
    const pose = () => ({ x: m(), y: m(), theta: angle() });
    if (u8() !== 1) throw new Error("not a compact snapshot");
    const flags = u8();
    const spectator = (flags & 1) !== 0, hasBelief = (flags & 2) !== 0, slow = (flags & 4) !== 0;
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
      if (slow) {
        const cloud = [];
        for (let k = u8(); k > 0; k--) cloud.push(u16(), u16());
        const scan = [];
        for (let k = u8(); k > 0; k--) scan.push(Math.round((u8() * 100) / 32));
        this.slow.set(id, { cloud, scan });
      }
      const kept = spectator && this.slow.get(id);
      if (kept) { r.cloud = kept.cloud; r.scan = kept.scan; }
      robots.push(r);
    }
    const opponents = [];
    for (let n = u8(); n > 0; n--) {
      const id = `o${u8()}`;
      const p = pose();
      const bits = u8();
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
      for (let n = u8(); n > 0; n--) {
        const role = { id: u32(), count: u8() };
        const bits = u8();
        role.tagged = (bits & 1) !== 0;
        role.state = STATE[(bits >> 1) & 3] || "invalid";
        role.confidence = Math.round((u8() / 255) * 100) / 100;
        role.particles = u32();
        role.mean = [m(), m()];
        const points = [];
        for (let k = u16(); k > 0; k--) points.push(u16(), u16());
        role.points = points;
        belief.roles.push(role);
      }
    }
    const winner = flags & 16 ? "robots" : flags & 32 ? "opponents" : null;
    const s = {
      type: "snapshot", tick, time_left_s: timeLeft, status: flags & 8 ? "finished" : "running", winner,
      view: spectator ? "spectator" : "player", you: you ? `o${you - 1}` : null, robots, opponents, score,
    };
    if (!spectator) s.ack = ack;
    if (belief) s.belief = belief;
    return s;
  }
}
