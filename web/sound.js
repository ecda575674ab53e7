// Sounds of a match, made in the page with Web Audio (no files): your tag landing, being
// tagged, a robot coming into view, a teammate's mark. Off by default; M (or the HUD's
// button) switches them, and the choice is remembered. The audio context starts on the
// first switch-on, a user gesture, as browsers require.

const KEY = "lasertag.sound";

/** Each sound: oscillator type, start and end frequency (Hz), length (s), loudness. */
const SOUNDS = {
  tag: ["square", 520, 1040, 0.16, 0.12],
  tagged: ["sawtooth", 220, 70, 0.45, 0.16],
  seen: ["sine", 1320, 1320, 0.07, 0.08],
  // A teammate's mark: a rising chirp for a robot seen, a bright blip for a way to go, a
  // low falling tone for a danger.
  mark_robot: ["triangle", 700, 1400, 0.14, 0.12],
  mark_go: ["sine", 990, 990, 0.1, 0.1],
  mark_danger: ["square", 440, 260, 0.22, 0.09],
};

export class Sound {
  constructor(button) {
    this.button = button;
    this.on = localStorage.getItem(KEY) === "on";
    this.ctx = null;
    this.played = [];
    this.button.onclick = () => { this.toggle(); this.button.blur(); };
    this.show();
  }

  toggle() {
    this.on = !this.on;
    localStorage.setItem(KEY, this.on ? "on" : "off");
    this.show();
  }

  show() {
    this.button.textContent = this.on ? "sound on (M)" : "sound off (M)";
    this.button.classList.toggle("on", this.on);
    const debug = (window.__lasertag = window.__lasertag || {});
    debug.sound = this.on;
  }

  /** Plays `kind` if sound is on (and remembers it for tests either way as `played`). */
  play(kind) {
    const debug = (window.__lasertag = window.__lasertag || {});
    (debug.sounds = debug.sounds || []).push(kind);
    if (!this.on || !SOUNDS[kind]) return;
    try {
      this.ctx = this.ctx || new AudioContext();
      const [type, f0, f1, length, gain] = SOUNDS[kind];
      const t = this.ctx.currentTime;
      const osc = this.ctx.createOscillator();
      const amp = this.ctx.createGain();
      osc.type = type;
      osc.frequency.setValueAtTime(f0, t);
      osc.frequency.exponentialRampToValueAtTime(f1, t + length);
      amp.gain.setValueAtTime(gain, t);
      amp.gain.exponentialRampToValueAtTime(0.001, t + length);
      osc.connect(amp).connect(this.ctx.destination);
      osc.start(t);
      osc.stop(t + length);
    } catch {
      // No audio on this device: the game goes on silently.
    }
  }
}
