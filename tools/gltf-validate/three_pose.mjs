#!/usr/bin/env node
// Loads a .glb with three.js' GLTFLoader (what the web viewer uses), plays its first
// animation to TIME seconds and prints the skinned mesh's vertex positions in world space:
//   node three_pose.mjs FILE.glb TIME
// Output, one JSON object: {"bones", "tracks", "unbound" (tracks whose target node three.js
// could not find), "positions" ([x, y, z, ...] of every vertex of the first skinned mesh)}.
// Exit status 2 when the file does not load or holds no skinned mesh.
import fs from 'fs';
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';

const [file, timeText] = process.argv.slice(2);
if (!file || timeText === undefined) {
  process.stderr.write('usage: three_pose.mjs FILE.glb TIME\n');
  process.exit(2);
}
const bytes = fs.readFileSync(file);
const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
new GLTFLoader().parse(
  buffer,
  '',
  (gltf) => {
    let mesh = null;
    gltf.scene.traverse((object) => {
      if (object.isSkinnedMesh && mesh === null) mesh = object;
    });
    if (mesh === null || gltf.animations.length === 0) {
      process.stderr.write(`${file}: no skinned mesh or no animation\n`);
      process.exit(2);
    }
    const clip = gltf.animations[0];
    let unbound = 0;
    for (const track of clip.tracks) {
      const binding = THREE.PropertyBinding.create(gltf.scene, track.name);
      binding.bind();
      if (!binding.node) unbound += 1;
    }
    const mixer = new THREE.AnimationMixer(gltf.scene);
    mixer.clipAction(clip).play();
    mixer.setTime(Number(timeText));
    gltf.scene.updateMatrixWorld(true);
    mesh.skeleton.update();
    const count = mesh.geometry.attributes.position.count;
    const positions = new Array(count * 3);
    const v = new THREE.Vector3();
    for (let i = 0; i < count; i += 1) {
      mesh.getVertexPosition(i, v);  // applies the bone transforms
      v.applyMatrix4(mesh.matrixWorld);
      positions[3 * i] = v.x;
      positions[3 * i + 1] = v.y;
      positions[3 * i + 2] = v.z;
    }
    process.stdout.write(JSON.stringify({
      bones: mesh.skeleton.bones.length, tracks: clip.tracks.length, unbound, positions,
    }) + '\n');
  },
  (error) => {
    process.stderr.write(`${file}: ${error.message || error}\n`);
    process.exit(2);
  },
);
