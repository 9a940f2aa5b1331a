// A motion player: a BVH clip drawn in 3D on its own skeleton (bones as rods, joints as balls),
// with orbiting, play/pause, scrubbing, speed and a download link. Browsers allow only a few
// WebGL contexts per page, so at most LIVE_LIMIT players draw at once; the oldest others are
// put to sleep (their place says so and wakes them on a click).

import * as THREE from './vendor/three.module.js';
import { BVHLoader } from './vendor/BVHLoader.js';
import { OrbitControls } from './vendor/OrbitControls.js';
import { element } from './dom.js';
import { qualityList } from './quality.js';

const LIVE_LIMIT = 8;
const SPEEDS = [0.25, 0.5, 1, 1.5, 2];
const live = [];

/** The skeleton and animation of a BVH text, with its frame count and frame time. */
export function parseBvh(text) {
  const frames = Number(/Frames:\s*(\d+)/.exec(text)?.[1]);
  const frameTime = Number(/Frame Time:\s*([0-9.eE+-]+)/.exec(text)?.[1]);
  if (!(frames > 0) || !(frameTime > 0)) throw new Error('This BVH has no frames to play.');
  const { skeleton, clip } = new BVHLoader().parse(text);
  return { root: skeleton.bones[0], clip, frames, frameTime };
}

/** The joint tree of a parsed BVH as nested { name, children } (end sites left out). */
export function jointTree(bone) {
  return {
    name: bone.name,
    children: bone.children.filter((c) => c.isBone && c.name !== 'ENDSITE').map(jointTree),
  };
}


/** Plays one BVH clip in a figure appended to `container`. */
export class Viewer {
  /**
   * @param {HTMLElement} container where the player goes
   * @param {string} text the BVH
   * @param {{title: string, download?: string, filename?: string, autoplay?: boolean, quality?: object}} options
   *   `quality`: the motion's quality report, listed under the player
   */
  constructor(container, text, options) {
    this.motion = parseBvh(text);
    this.title = options.title;
    this.time = 0;
    this.speed = 1;
    this.playing = options.autoplay !== false;
    this.figure = element('figure', { class: 'viewer' });
    this.stage = element('div', { class: 'stage' });
    this.figure.append(this.stage, element('figcaption', {}, options.title), this.controls(options));
    if (options.quality) {
      this.figure.dataset.quality = JSON.stringify(options.quality);
      this.figure.append(qualityList(options.quality));
    }
    container.append(this.figure);
    this.wake();
  }

  controls(options) {
    const { frames } = this.motion;
    const bar = element('div', { class: 'controls' });
    this.playButton = element('button', { type: 'button', class: 'play' });
    this.playButton.addEventListener('click', () => this.setPlaying(!this.playing));
    this.scrub = element('input', {
      type: 'range', class: 'scrub', min: '0', max: String(frames - 1), step: '1', value: '0',
      'aria-label': `Frame of ${this.title}`,
    });
    this.scrub.addEventListener('input', () => {
      this.setPlaying(false);
      this.seekFrame(Number(this.scrub.value));
    });
    this.counter = element('output', { class: 'frame', 'data-frame': '0' });
    const speedLabel = element('label', { class: 'speed' }, 'Speed ');
    this.speedSelect = element('select', { 'aria-label': `Playback speed of ${this.title}` });
    for (const s of SPEEDS) {
      const option = element('option', { value: String(s) }, `${s}×`);
      if (s === 1) option.selected = true;
      this.speedSelect.append(option);
    }
    this.speedSelect.addEventListener('change', () => { this.speed = Number(this.speedSelect.value); });
    speedLabel.append(this.speedSelect);
    bar.append(this.playButton, this.scrub, this.counter, speedLabel);
    if (options.download) {
      bar.append(element('a', { class: 'download', href: options.download, download: options.filename || 'motion.bvh' }, 'Download BVH'));
    }
    this.figure.addEventListener('keydown', (e) => this.key(e));
    this.showState();
    return bar;
  }

  key(e) {
    if (e.target instanceof HTMLInputElement || e.target instanceof HTMLSelectElement) return;
    const step = { ArrowLeft: -1, ArrowRight: 1 }[e.key];
    if (e.key === ' ' || e.key === 'k') {
      if (e.target instanceof HTMLButtonElement || e.target instanceof HTMLAnchorElement) return;
      this.setPlaying(!this.playing);
    } else if (step) {
      this.setPlaying(false);
      this.seekFrame(this.frame() + step);
    } else if (e.key === 'Home' || e.key === 'End') {
      this.setPlaying(false);
      this.seekFrame(e.key === 'Home' ? 0 : this.motion.frames - 1);
    } else {
      return;
    }
    e.preventDefault();
  }

  /** Starts drawing (making the WebGL context), putting the oldest player to sleep if need be. */
  wake() {
    if (this.renderer) return;
    while (live.length >= LIVE_LIMIT) live[0].sleep();
    this.stage.replaceChildren();
    let renderer;
    try {
      renderer = new THREE.WebGLRenderer({ antialias: true });
    } catch {
      this.stage.append(element('p', { class: 'error', role: 'alert' },
        'This browser could not start WebGL, so the motion cannot be drawn here; the BVH can still be downloaded.'));
      return;
    }
    this.renderer = renderer;
    renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    const canvas = renderer.domElement;
    canvas.tabIndex = 0;
    canvas.setAttribute('role', 'img');
    canvas.setAttribute('aria-label',
      `${this.title}, in 3D: drag to orbit, scroll to zoom; space plays or pauses, arrow keys step a frame`);
    this.stage.append(canvas);
    this.build();
    this.resize = new ResizeObserver(() => this.fit());
    this.resize.observe(this.stage);
    this.fit();
    live.push(this);
    this.apply();
    startLoop();
  }

  /** Frees the WebGL context; the stage offers to wake the player again. */
  sleep() {
    if (!this.renderer) return;
    live.splice(live.indexOf(this), 1);
    this.resize.disconnect();
    this.orbit.dispose();
    this.scene.traverse((o) => {
      o.geometry?.dispose();
      o.material?.dispose();
    });
    this.renderer.dispose();
    this.renderer.forceContextLoss();
    this.renderer = null;
    const wake = element('button', { type: 'button', class: 'wake' }, `Show ${this.title} again`);
    wake.addEventListener('click', () => { this.wake(); this.focus(); });
    this.stage.replaceChildren(wake);
  }

  /** Moves the keyboard focus to the player (its canvas, or its play button without WebGL). */
  focus() {
    (this.renderer?.domElement ?? this.playButton).focus();
  }

  /** Stops drawing and removes the player. */
  remove() {
    this.sleep();
    this.figure.remove();
  }

  build() {
    const { root, clip } = this.motion;
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xf4f5f7);
    this.holder = new THREE.Group();
    this.holder.add(root);
    this.scene.add(this.holder);
    this.mixer = new THREE.AnimationMixer(this.holder);
    this.mixer.clipAction(clip).play();
    // A root with one child is a placement handle (a ground reference, as many rigs have), not
    // a bone: its ball is drawn, but no rod to it.
    const handle = root.children.filter((c) => c.isBone).length === 1;
    this.links = [];
    root.traverse((b) => {
      if (b !== root && b.parent?.isBone && !(handle && b.parent === root)) this.links.push([b.parent, b]);
    });
    this.joints = [];
    root.traverse((b) => { if (b.isBone) this.joints.push(b); });

    const box = this.extent();
    const size = box.getSize(new THREE.Vector3());
    const reach = Math.max(size.x, size.y, size.z, 1e-3);
    const center = box.getCenter(new THREE.Vector3());
    const height = this.restHeight(reach);
    const radius = height * 0.018;
    const rod = new THREE.CylinderGeometry(radius, radius, 1, 8);
    const ball = new THREE.SphereGeometry(radius * 1.6, 12, 8);
    this.rods = new THREE.InstancedMesh(rod, new THREE.MeshStandardMaterial({ color: 0x3b6fd8, roughness: 0.6 }), Math.max(this.links.length, 1));
    this.balls = new THREE.InstancedMesh(ball, new THREE.MeshStandardMaterial({ color: 0xe0703a, roughness: 0.5 }), this.joints.length);
    this.rods.frustumCulled = false;
    this.balls.frustumCulled = false;
    this.scene.add(this.rods, this.balls);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8890a0, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(1, 2, 1.5);
    this.scene.add(sun);
    const grid = new THREE.GridHelper(reach * 3, 24, 0xa0a6b0, 0xd0d4da);
    grid.position.set(center.x, box.min.y, center.z);
    this.scene.add(grid);

    this.camera = new THREE.PerspectiveCamera(40, 1, reach * 0.01, reach * 50);
    this.camera.position.set(center.x + reach * 0.9, center.y + reach * 0.45, center.z + reach * 1.4);
    this.orbit = new OrbitControls(this.camera, this.renderer.domElement);
    this.orbit.target.copy(center);
    this.orbit.update();
  }

  /** The box the joints sweep over the whole clip (sampled), so the camera frames all of it. */
  extent() {
    const box = new THREE.Box3();
    const p = new THREE.Vector3();
    const samples = Math.min(this.motion.frames, 48);
    const duration = (this.motion.frames - 1) * this.motion.frameTime;
    for (let i = 0; i < samples; i++) {
      this.mixer.setTime(samples > 1 ? (duration * i) / (samples - 1) : 0);
      this.holder.updateMatrixWorld(true);
      for (const j of this.joints) box.expandByPoint(j.getWorldPosition(p));
    }
    return box;
  }

  /** The skeleton's own height in its first pose, for the thickness of its bones. */
  restHeight(fallback) {
    this.mixer.setTime(0);
    this.holder.updateMatrixWorld(true);
    const box = new THREE.Box3();
    const p = new THREE.Vector3();
    for (const j of this.joints) box.expandByPoint(j.getWorldPosition(p));
    const s = box.getSize(p);
    return Math.max(s.x, s.y, s.z) || fallback;
  }

  fit() {
    if (!this.renderer) return;
    const w = this.stage.clientWidth;
    const h = this.stage.clientHeight;
    if (!w || !h) return;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
  }

  duration() {
    return (this.motion.frames - 1) * this.motion.frameTime;
  }

  frame() {
    return Math.min(this.motion.frames - 1, Math.floor(this.time / this.motion.frameTime + 1e-6));
  }

  /** Jumps to a frame (clamped to the clip). */
  seekFrame(frame) {
    const f = Math.max(0, Math.min(this.motion.frames - 1, frame));
    this.time = f * this.motion.frameTime;
    this.apply();
  }

  /** Restarts from the first frame, playing. */
  restart() {
    this.seekFrame(0);
    this.setPlaying(true);
  }

  setPlaying(playing) {
    this.playing = playing && this.motion.frames > 1;
    this.showState();
  }

  showState() {
    this.playButton.textContent = this.playing ? 'Pause' : 'Play';
    this.playButton.setAttribute('aria-label', `${this.playing ? 'Pause' : 'Play'} ${this.title}`);
  }

  /** Advances by a wall-clock step when playing, then draws. */
  tick(seconds) {
    if (this.playing) {
      const d = this.duration();
      this.time = d > 0 ? (this.time + seconds * this.speed) % d : 0;
      this.apply();
    }
    if (this.stage.clientWidth) this.renderer.render(this.scene, this.camera);
  }

  /** Poses the skeleton at the current time and shows the frame. */
  apply() {
    const frame = this.frame();
    this.counter.textContent = `${frame + 1} / ${this.motion.frames}`;
    this.counter.dataset.frame = String(frame);
    if (document.activeElement !== this.scrub) this.scrub.value = String(frame);
    if (!this.renderer) return;
    this.mixer.setTime(this.time);
    this.holder.updateMatrixWorld(true);
    const a = new THREE.Vector3();
    const b = new THREE.Vector3();
    const m = new THREE.Matrix4();
    const q = new THREE.Quaternion();
    const up = new THREE.Vector3(0, 1, 0);
    const s = new THREE.Vector3();
    this.links.forEach(([parent, child], i) => {
      parent.getWorldPosition(a);
      child.getWorldPosition(b);
      const length = a.distanceTo(b);
      const mid = a.clone().add(b).multiplyScalar(0.5);
      q.setFromUnitVectors(up, b.sub(a).normalize());
      m.compose(mid, q, s.set(1, length, 1));
      this.rods.setMatrixAt(i, m);
    });
    this.rods.instanceMatrix.needsUpdate = true;
    this.joints.forEach((j, i) => {
      m.compose(j.getWorldPosition(a), q.identity(), s.set(1, 1, 1));
      this.balls.setMatrixAt(i, m);
    });
    this.balls.instanceMatrix.needsUpdate = true;
  }
}

let looping = false;

/** One animation loop for every live player. */
function startLoop() {
  if (looping) return;
  looping = true;
  let last = performance.now();
  const step = (now) => {
    const seconds = Math.min((now - last) / 1000, 0.1);
    last = now;
    for (const v of live) v.tick(seconds);
    if (live.length) requestAnimationFrame(step);
    else looping = false;
  };
  requestAnimationFrame(step);
}
