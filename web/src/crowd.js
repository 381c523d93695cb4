// A crowd in the spirit of the paper's fig. 9: characters on a field receding from the
// camera, each drawn with the level its on-screen height selects and playing one of the
// bake's clips (round robin). Each level and clip has a few animated templates (phases of
// the clip); every character follows one of them and is an instance of that template's
// skinned pose (see makeTemplates).
import * as THREE from 'three';
import { clone as cloneSkinned } from 'three/addons/utils/SkeletonUtils.js';
import { levelForPixels } from './level_choice.js';
import { measure, pickClip } from './models.js';

const kPhases = 3;
export const kLevelColours = ['#2f6fde', '#22a06b', '#e0a800', '#e8590c', '#c2255c', '#7048e8', '#0c8599', '#5c940d'];

export class CrowdView {
  constructor(canvas) {
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(1);
    this.renderer.setSize(canvas.width, canvas.height, false);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xe9ecf2);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8d8d9a, 2.4));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(3, 6, 2);
    this.scene.add(sun);
    this.camera = new THREE.PerspectiveCamera(40, canvas.width / canvas.height, 0.05, 2000);
    this.clock = new THREE.Clock();
    this.templates = new Map();  // "level/clip" -> one template per phase (makeTemplates)
    this.members = [];           // { level, joints, px, distance, clip } per character
    this.field = new THREE.Group();
    this.scene.add(this.field);
    this.counts = new Map();
  }

  // `levels`: the bake's level table; `clips`: the clips the characters play in turn,
  // each { name, levelGltfs: level index -> its loaded glTF of the clip, or null (then the
  // first loaded one stands in) }.
  build({ levels, clips, count, colourByLevel }) {
    this.scene.remove(this.field);
    for (const phases of this.templates.values()) {
      for (const template of phases) for (const pose of template.poses) pose.geometry.dispose();
    }
    this.field = new THREE.Group();
    this.scene.add(this.field);
    this.templates = new Map();
    this.members = [];
    this.counts = new Map();

    const first = clips.flatMap((clip) => clip.levelGltfs).find((gltf) => gltf);
    if (!first) return;
    const { height } = measure(first.scene);
    // The camera stands 3 heights up and looks down the field; rows recede ever faster so
    // that on-screen heights run from about 100 px at the front to a few pixels at the back.
    const canvas = this.renderer.domElement;
    const tanHalf = Math.tan(THREE.MathUtils.degToRad(this.camera.fov) / 2);
    const focal = canvas.height / (2 * tanHalf);
    const halfWidthPerDepth = tanHalf * (canvas.width / canvas.height);
    this.camera.position.set(0, height * 3, 0);
    this.camera.lookAt(0, 0, -height * 14);
    this.camera.near = height * 0.5;
    this.camera.far = height * 400;
    this.camera.updateProjectionMatrix();
    this.camera.updateMatrixWorld();

    const columns = Math.max(4, Math.round(Math.sqrt(count * 1.4)));
    const random = mulberry32(7);
    const slots = [];
    for (let k = 0; k < count; ++k) {
      const row = Math.floor(k / columns);
      const depth = height * (5 + 0.5 * row ** 1.8);
      const across = ((k % columns) + 0.5) / columns - 0.5 + (random() - 0.5) * 0.6 / columns;
      const position = new THREE.Vector3(across * 1.8 * halfWidthPerDepth * depth, 0, -depth);
      const distance = position.clone().setY(height / 2).distanceTo(this.camera.position);
      slots.push({ position, px: (height * focal) / distance, distance, yaw: random() * Math.PI * 2 });
    }

    const materials = new Map();
    const materialFor = (levelIndex, original) => {
      if (!colourByLevel) return original;
      if (!materials.has(levelIndex)) {
        materials.set(levelIndex, new THREE.MeshLambertMaterial({ color: kLevelColours[levelIndex % kLevelColours.length] }));
      }
      return materials.get(levelIndex);
    };

    // Which template (level, phase) each character follows, then one instanced mesh per
    // template mesh holding every character that follows it.
    const followers = new Map();  // template -> [slot]
    slots.forEach((slot, k) => {
      const level = levelForPixels(levels, slot.px);
      const clip = clips[k % clips.length];
      const key = `${level.index}/${clip.name}`;
      if (!this.templates.has(key)) {
        const gltf = clip.levelGltfs[level.index] || clip.levelGltfs.find((g) => g) || first;
        this.templates.set(key, this.makeTemplates(gltf, clip.name));
      }
      const template = this.templates.get(key)[Math.floor(k / clips.length) % kPhases];
      if (!followers.has(template)) followers.set(template, { level: level.index, slots: [] });
      followers.get(template).slots.push(slot);
      this.members.push({ level: level.index, joints: level.joints, px: slot.px, distance: slot.distance, clip: clip.name });
      this.counts.set(level.index, (this.counts.get(level.index) || 0) + 1);
    });
    const placement = new THREE.Object3D();
    for (const [template, { level, slots: followed }] of followers) {
      for (const pose of template.poses) {
        const crowd = new THREE.InstancedMesh(pose.geometry, materialFor(level, pose.source.material), followed.length);
        followed.forEach((slot, k) => {
          placement.position.copy(slot.position);
          placement.rotation.set(0, slot.yaw, 0);
          placement.updateMatrix();
          crowd.setMatrixAt(k, placement.matrix);
        });
        crowd.frustumCulled = false;  // the pose moves; the bounds of the bind pose do not hold
        this.field.add(crowd);
      }
    }
  }

  // Templates are animated, not drawn: each skinned mesh of a template is skinned on the
  // CPU once a frame into a plain "pose" geometry (positions and normals in the model's
  // frame), which an InstancedMesh then draws for every character that follows it. Software
  // WebGL pays a few bone-texture reads per vertex and per character for GPU skinning; this
  // pays them once per template.
  makeTemplates(gltf, animation) {
    const phases = [];
    for (let phase = 0; phase < kPhases; ++phase) {
      const model = cloneSkinned(gltf.scene);
      model.updateMatrixWorld(true);
      const mixer = new THREE.AnimationMixer(model);
      const clip = pickClip(gltf, animation);
      if (clip) {
        const action = mixer.clipAction(clip).play();
        action.time = (clip.duration * phase) / kPhases;
      }
      const poses = [];
      model.traverse((object) => {
        if (!object.isSkinnedMesh) return;
        const geometry = new THREE.BufferGeometry();
        geometry.setIndex(object.geometry.index);
        for (const name of ['position', 'normal']) {
          const attribute = object.geometry.getAttribute(name);
          if (attribute) geometry.setAttribute(name, new THREE.Float32BufferAttribute(attribute.count * 3, 3));
        }
        const uv = object.geometry.getAttribute('uv');
        if (uv) geometry.setAttribute('uv', uv);
        for (const group of object.geometry.groups) geometry.addGroup(group.start, group.count, group.materialIndex);
        poses.push({ source: object, geometry, blend: [] });
      });
      const template = { model, mixer, poses };
      skinPoses(template);
      phases.push(template);
    }
    return phases;
  }

  tick() {
    const dt = Math.min(this.clock.getDelta(), 0.1);
    for (const phases of this.templates.values()) {
      for (const template of phases) {
        template.mixer.update(dt);
        skinPoses(template);
      }
    }
    this.renderer.render(this.scene, this.camera);
  }
}

// Linear blend skinning of a template's meshes into their pose geometries, in the frame
// of the template's root (which stands at the origin): for bone b, K_b = W B^-1 M_b A_b B,
// with W the mesh's world matrix, B its bind matrix, M_b the bone's world matrix and A_b
// its inverse bind matrix; a vertex is sum_b w_b K_b p, a normal the same with K_b's
// rotation part, normalised.
const _vertex = new THREE.Vector3();
const _normal = new THREE.Vector3();
function skinPoses(template) {
  template.model.updateMatrixWorld(true);
  for (const pose of template.poses) {
    const mesh = pose.source;
    const { bones, boneInverses } = mesh.skeleton;
    const meshFrame = new THREE.Matrix4().multiplyMatrices(mesh.matrixWorld, mesh.bindMatrixInverse);
    const blend = bones.map((bone, b) =>
      (pose.blend[b] ??= new THREE.Matrix4())
        .multiplyMatrices(bone.matrixWorld, boneInverses[b])
        .premultiply(meshFrame)
        .multiply(mesh.bindMatrix).elements,
    );
    const { position: restPosition, normal: restNormal, skinIndex, skinWeight } = mesh.geometry.attributes;
    const position = pose.geometry.attributes.position.array;
    const normal = pose.geometry.attributes.normal?.array;
    for (let v = 0; v < restPosition.count; ++v) {
      const px = restPosition.getX(v), py = restPosition.getY(v), pz = restPosition.getZ(v);
      let nx = 0, ny = 0, nz = 0;
      if (normal) {
        nx = restNormal.getX(v);
        ny = restNormal.getY(v);
        nz = restNormal.getZ(v);
      }
      _vertex.set(0, 0, 0);
      _normal.set(0, 0, 0);
      for (let i = 0; i < 4; ++i) {
        const w = skinWeight.getComponent(v, i);
        if (w === 0) continue;
        const e = blend[skinIndex.getComponent(v, i)];
        _vertex.x += w * (e[0] * px + e[4] * py + e[8] * pz + e[12]);
        _vertex.y += w * (e[1] * px + e[5] * py + e[9] * pz + e[13]);
        _vertex.z += w * (e[2] * px + e[6] * py + e[10] * pz + e[14]);
        _normal.x += w * (e[0] * nx + e[4] * ny + e[8] * nz);
        _normal.y += w * (e[1] * nx + e[5] * ny + e[9] * nz);
        _normal.z += w * (e[2] * nx + e[6] * ny + e[10] * nz);
      }
      position[3 * v] = _vertex.x;
      position[3 * v + 1] = _vertex.y;
      position[3 * v + 2] = _vertex.z;
      if (normal) {
        _normal.normalize();
        normal[3 * v] = _normal.x;
        normal[3 * v + 1] = _normal.y;
        normal[3 * v + 2] = _normal.z;
      }
    }
    pose.geometry.attributes.position.needsUpdate = true;
    if (normal) pose.geometry.attributes.normal.needsUpdate = true;
  }
}

// A small seeded generator: the same crowd every time.
function mulberry32(seed) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}
