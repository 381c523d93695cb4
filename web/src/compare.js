// Two views side by side, the original and one level, playing the same clip on one
// clock: both mixers advance by the same time step, and a newly shown level starts at the
// original's time.
import * as THREE from 'three';
import { measure, pickClip } from './models.js';

// True when WebGL runs on the CPU (SwiftShader, llvmpipe): then multisampling, which
// costs several times the fill, is left off.
export const softwareRendering = (() => {
  const gl = document.createElement('canvas').getContext('webgl2');
  const info = gl?.getExtension('WEBGL_debug_renderer_info');
  const renderer = info ? String(gl.getParameter(info.UNMASKED_RENDERER_WEBGL)) : '';
  return /swiftshader|llvmpipe|software/i.test(renderer);
})();

function makeView(canvas) {
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: !softwareRendering, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(canvas.width, canvas.height, false);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xe9ecf2);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8d8d9a, 2.2));
  const sun = new THREE.DirectionalLight(0xffffff, 2.0);
  sun.position.set(2, 4, 3);
  scene.add(sun);
  const camera = new THREE.PerspectiveCamera(35, canvas.width / canvas.height, 0.01, 1000);
  return { renderer, scene, camera, model: null, mixer: null, action: null, bones: 0 };
}

export class CompareView {
  constructor(originalCanvas, levelCanvas) {
    this.original = makeView(originalCanvas);
    this.level = makeView(levelCanvas);
    this.clock = new THREE.Clock();
    this.frames = 0;
  }

  // Puts a loaded glTF into a view, framed by the original's bounds so both views share
  // one camera framing (by the level's while there is no original, else nothing frames it).
  show(view, gltf, animation, bones) {
    if (view.model) view.scene.remove(view.model);
    view.mixer?.stopAllAction();
    view.model = gltf.scene;
    view.bones = bones;
    view.scene.add(view.model);
    const clip = pickClip(gltf, animation);
    view.mixer = new THREE.AnimationMixer(view.model);
    view.action = clip ? view.mixer.clipAction(clip).play() : null;
    if (view === this.original || !this.original.model) this.frame(measure(view.model));
    if (view === this.level && this.original.action && view.action) {
      view.action.time = this.original.action.time;
    }
  }

  clear(view) {
    if (view.model) view.scene.remove(view.model);
    view.model = null;
    view.mixer = null;
    view.action = null;
    view.bones = 0;
  }

  frame({ height, centre }) {
    for (const view of [this.original, this.level]) {
      const distance = (height * 1.35) / (2 * Math.tan(THREE.MathUtils.degToRad(view.camera.fov) / 2));
      view.camera.position.set(centre.x + distance * 0.35, centre.y + height * 0.1, centre.z + distance);
      view.camera.near = distance / 100;
      view.camera.far = distance * 10;
      view.camera.updateProjectionMatrix();
      view.camera.lookAt(centre);
    }
  }

  tick() {
    const dt = Math.min(this.clock.getDelta(), 0.1);
    for (const view of [this.original, this.level]) {
      view.mixer?.update(dt);
      view.renderer.render(view.scene, view.camera);
    }
    this.frames += 1;
  }
}
