// Touch controls for phones and tablets: a virtual stick (drive and turn, as W A S D) at the
// bottom left and a tag button (as Space) at the bottom right, over the arena. Pointer events,
// so a mouse drives them too; shown to a player on a device with a touch screen.

const $ = (id) => document.getElementById(id);

/** Whether this device has a touch screen (or a browser emulating one). */
export function touchScreen() {
  return navigator.maxTouchPoints > 0 || "ontouchstart" in window || matchMedia("(pointer: coarse)").matches;
}

export class TouchPad {
  /** `onTag()` fires on every press of the tag button. */
  constructor({ onTag }) {
    this.forward = 0;
    this.turn = 0;
    this.stick = $("touch-stick");
    this.knob = $("touch-knob");
    this.fire = $("touch-tag");
    this.pointer = null;
    this.onDown = (e) => this.down(e);
    this.onMove = (e) => this.move(e);
    this.onUp = (e) => this.up(e);
    this.onFire = (e) => {
      e.preventDefault();
      this.fire.classList.add("on");
      onTag();
    };
    this.onFireUp = () => this.fire.classList.remove("on");
    this.stick.addEventListener("pointerdown", this.onDown);
    window.addEventListener("pointermove", this.onMove);
    window.addEventListener("pointerup", this.onUp);
    window.addEventListener("pointercancel", this.onUp);
    this.fire.addEventListener("pointerdown", this.onFire);
    this.fire.addEventListener("pointerup", this.onFireUp);
    $("touch").hidden = false;
  }

  stop() {
    this.stick.removeEventListener("pointerdown", this.onDown);
    window.removeEventListener("pointermove", this.onMove);
    window.removeEventListener("pointerup", this.onUp);
    window.removeEventListener("pointercancel", this.onUp);
    this.fire.removeEventListener("pointerdown", this.onFire);
    this.fire.removeEventListener("pointerup", this.onFireUp);
    $("touch").hidden = true;
    this.release();
  }

  down(e) {
    e.preventDefault();
    this.pointer = e.pointerId;
    this.move(e);
  }

  /** The knob follows the finger within the stick's ring: up drives forward, left turns
   * left, each in proportion to how far it is pushed (a small dead zone at the centre). */
  move(e) {
    if (e.pointerId !== this.pointer) return;
    const r = this.stick.getBoundingClientRect();
    const radius = r.width / 2;
    let dx = e.clientX - (r.left + radius);
    let dy = e.clientY - (r.top + radius);
    const d = Math.hypot(dx, dy);
    if (d > radius) { dx *= radius / d; dy *= radius / d; }
    this.knob.style.transform = `translate(${dx}px, ${dy}px)`;
    const axis = (v) => (Math.abs(v) < 0.15 ? 0 : Math.max(-1, Math.min(1, v)));
    this.forward = axis(-dy / radius);
    this.turn = axis(-dx / radius);
  }

  up(e) {
    if (e.pointerId !== this.pointer) return;
    this.release();
  }

  release() {
    this.pointer = null;
    this.forward = 0;
    this.turn = 0;
    this.knob.style.transform = "";
  }
}
