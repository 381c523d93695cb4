// Loading the glTF export of a bake's levels (GET /v1/bakes/{id}/levels/{hash}.glb).
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { ApiError, authHeaders } from './api.js';

const loader = new GLTFLoader();

// A level of the bake's level table (its own mesh, influences and pose rate, named by its
// hash: several levels may keep the same joints), playing the clip named `clip` (the first
// when empty).
export function levelUrl(bakeId, level, clip = '') {
  return `/v1/bakes/${bakeId}/levels/${level.hash}.glb${clip ? `?clip=${encodeURIComponent(clip)}` : ''}`;
}

// Fetches a GLB from the daemon; failures become ApiErrors with the problem's detail.
export async function fetchGlb(url) {
  const response = await fetch(url, { headers: authHeaders() });
  if (!response.ok) {
    const body = await response.json().catch(() => null);
    throw new ApiError(response.status, body?.title || response.statusText, body?.detail || '');
  }
  return response.arrayBuffer();
}

// A fresh scene graph from GLB bytes (each view needs its own).
export function parseGlb(buffer) {
  return new Promise((resolve, reject) =>
    loader.parse(buffer, '', resolve, (error) =>
      reject(new ApiError(0, 'unreadable glTF', String(error?.message || error))),
    ),
  );
}

// The joints of a loaded glTF's skins (the union over its skinned meshes).
export function jointCount(gltf) {
  const bones = new Set();
  gltf.scene.traverse((object) => {
    if (object.isSkinnedMesh) for (const bone of object.skeleton.bones) bones.add(bone);
  });
  return bones.size;
}

// The clip to play: the one named `animation` (a clip of the bake), else the first.
export function pickClip(gltf, animation) {
  return gltf.animations.find((clip) => clip.name === animation) || gltf.animations[0] || null;
}

// Height (model units) and centre of the model's bind pose.
export function measure(object) {
  const box = new THREE.Box3().setFromObject(object);
  const size = box.getSize(new THREE.Vector3());
  return { box, size, height: Math.max(size.x, size.y, size.z), centre: box.getCenter(new THREE.Vector3()) };
}
