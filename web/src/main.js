// The motionlod viewer: upload a character, bake it, compare a level with the original,
// plot the error curve and the joint priorities, and draw a crowd at mixed levels.
import { ApiError, getJson, postJson, setApiKey, uploadFiles, waitForJob } from './api.js';
import { drawCurves } from './chart.js';
import { CompareView } from './compare.js';
import { CrowdView, kLevelColours } from './crowd.js';
import { fetchGlb, jointCount, levelUrl, parseGlb } from './models.js';

const $ = (id) => document.getElementById(id);

// What the page shows; also read by the end-to-end test (window.motionlodViewer).
const state = {
  character: null, // GET /v1/characters/{id}
  localFiles: [], // the files the character was uploaded from (a stand-in original)
  bake: null, // GET /v1/bakes/{id}
  report: null, // GET /v1/bakes/{id}/report
  levelIndex: 0,
  clip: '', // the clip the views play (an animation name of the bake)
  levelBuffers: [], // per level index: its glTF export's bytes for the clip, or null
  originalBuffer: null, // the finest level's export (all joints when baked), else the uploaded .glb, else null
  originalJoints: null, // the joints of what the left view shows (null: nothing)
  crowdGltfs: [], // per level index: a parsed export of the clip for the crowd's templates
  crowdClips: [], // the clips the crowd plays, round robin: { name, levelGltfs }
  exportError: '', // why the level exports could not be loaded
  busy: false,
};

let compare = null;
let crowd = null;
try {
  compare = new CompareView($('view-original'), $('view-level'));
  crowd = new CrowdView($('view-crowd'));
} catch (error) {
  showError(new ApiError(0, 'WebGL is not available', `this browser cannot draw the 3D views (${error.message})`));
}

window.motionlodViewer = {
  state,
  get compareFrames() { return compare ? compare.frames : 0; },
  get crowdMembers() {
    return crowd ? crowd.members.map(({ level, joints, px, clip }) => ({ level, joints, px, clip })) : [];
  },
  // The clip each view plays.
  get playing() {
    return compare
      ? { original: compare.original.action?.getClip().name ?? null, level: compare.level.action?.getClip().name ?? null }
      : null;
  },
  get viewBones() {
    return compare ? { original: compare.original.bones, level: compare.level.bones } : null;
  },
};

// Shows a failure: the daemon's problem title, status and detail for an ApiError.
function showError(error, context = '') {
  const box = $('error');
  if (error instanceof ApiError) {
    const status = error.status ? ` (HTTP ${error.status})` : '';
    box.textContent = `${context}${error.title}${status}${error.detail ? `: ${error.detail}` : ''}`;
  } else {
    box.textContent = `${context}${error.message}`;
  }
  box.hidden = false;
  box.scrollIntoView({ block: 'nearest' });
}
function clearError() {
  $('error').hidden = true;
  $('error').textContent = '';
}
function setProgress(fraction, text) {
  $('progress').value = fraction;
  $('progress-text').textContent = text;
}
const format = (value, digits) => (value === null || value === undefined ? '—' : Number(value).toFixed(digits));
// "(px_min, px_max] px" in tenths of a pixel; a sliver that would read as an empty range
// such as (71.0, 71.0] (two levels whose errors differ in the fifth digit) says so.
function pixelRange(pxMin, pxMax) {
  if (pxMax === null) return `(${format(pxMin, 1)}, ∞] px`;
  if (format(pxMin, 1) === format(pxMax, 1)) return `only about ${format(pxMax, 1)} px (a coarser level is almost as accurate)`;
  return `(${format(pxMin, 1)}, ${format(pxMax, 1)}] px`;
}

// ---- 1. Upload ------------------------------------------------------------------------

async function upload(files) {
  if (files.length === 0 || state.busy) return;
  clearError();
  state.busy = true;
  setProgress(0, 'uploading…');
  try {
    const character = await uploadFiles('/v1/characters', files, (fraction) =>
      setProgress(fraction * 0.5, `uploading ${Math.round(fraction * 100)}%`),
    );
    state.localFiles = files;
    setProgress(0, 'uploaded');
    await showCharacter(character);
  } catch (error) {
    setProgress(0, 'upload failed');
    showError(error, `Upload of ${files.map((f) => f.name).join(', ')} failed: `);
  } finally {
    state.busy = false;
  }
}

async function showCharacter(character) {
  state.character = character;
  $('character-summary').textContent =
    `${character.name}: ${character.joints} joints, ${character.vertices} vertices, ` +
    `${character.triangles} triangles${character.proxy_skin ? ' (no mesh: a proxy skin of capsules)' : ''}` +
    `${character.warnings.length ? ` — ${character.warnings.join('; ')}` : ''}`;
  $('bake-panel').hidden = false;
  const { motions } = await getJson(`/v1/characters/${character.id}/motions`);
  const select = $('motion');
  select.replaceChildren();
  for (const motion of motions) {
    const option = new Option(
      `${motion.animation} (${motion.duration_seconds.toFixed(2)} s${motion.source === 'file' ? `, ${motion.files[0]?.name}` : ''})`,
      motion.id,
    );
    select.append(option);
  }
  // No motion in the request: the daemon bakes every motion of the character together.
  if (motions.length > 1) select.append(new Option(`every animation together (${motions.length} clips)`, ''));
  $('bake-button').disabled = motions.length === 0;
  if (motions.length === 0) {
    showError(new ApiError(0, 'nothing to bake', 'this character has no animation: add a motion file (BVH, FBX, glTF)'));
  }
}

async function addMotion(file) {
  if (!state.character || !file) return;
  clearError();
  try {
    const { motions } = await uploadFiles(`/v1/motions?character=${state.character.id}`, [file], (fraction) =>
      setProgress(fraction, `uploading ${file.name}`),
    );
    setProgress(0, `${file.name} added`);
    await showCharacter(state.character);
    if (motions.length) $('motion').value = motions[0].id;
  } catch (error) {
    showError(error, `The motion ${file.name} was refused: `);
  }
}

// ---- 2. Bake ----------------------------------------------------------------------------

function parseLevels(text) {
  const trimmed = text.trim();
  if (!trimmed) return [];
  const levels = trimmed.split(/[\s,]+/).map(Number);
  if (levels.some((n) => !Number.isInteger(n) || n < 1)) {
    throw new ApiError(0, 'bad levels', `"${text}" is not a list of joint counts such as 20,12,6`);
  }
  return levels;
}

async function bake() {
  if (!state.character || state.busy) return;
  clearError();
  state.busy = true;
  $('bake-button').disabled = true;
  try {
    const request = { character: state.character.id, variant: $('variant').value };
    if ($('motion').value) request.motion = $('motion').value;
    const levels = parseLevels($('levels').value);
    if (levels.length) request.levels = levels;
    const job = await postJson('/v1/bakes', request);
    const status = await waitForJob(job.id, (s) =>
      setProgress(s.progress, `${s.state}${s.stage ? ` — ${s.stage}` : ''} ${Math.round(s.progress * 100)}%`),
    );
    if (status.state === 'failed') {
      throw new ApiError(0, `bake failed (${status.error?.code || 'error'})`, status.error?.detail || '');
    }
    setProgress(1, 'baked');
    await openBake(job.id);
  } catch (error) {
    showError(error, 'Bake: ');
  } finally {
    state.busy = false;
    $('bake-button').disabled = false;
  }
}

// ---- 3. Levels --------------------------------------------------------------------------

async function openBake(bakeId) {
  clearError();
  const bake = await getJson(`/v1/bakes/${bakeId}`);
  if (bake.state !== 'succeeded') {
    showError(new ApiError(0, `bake ${bake.state}`, 'the bake has not succeeded: nothing to show yet'));
    return;
  }
  const [report, character] = await Promise.all([
    getJson(`/v1/bakes/${bakeId}/report`),
    state.character?.id === bake.character ? state.character : getJson(`/v1/characters/${bake.character}`),
  ]);
  if (state.character?.id !== character.id) {
    state.localFiles = [];
    await showCharacter(character);
  }
  state.bake = bake;
  state.report = report;
  state.exportError = '';
  window.location.hash = `bake=${bakeId}`;
  for (const id of ['compare', 'curves', 'crowd']) $(id).hidden = false;
  fillRanking();
  await listBakes();
  state.clip = bake.clips[0]?.animation ?? bake.animation;
  const clips = $('clip');
  clips.replaceChildren(...bake.clips.map((clip) =>
    new Option(`${clip.animation} (${clip.frames} frames)`, clip.animation, false, clip.animation === state.clip)));
  $('clip-field').hidden = bake.clips.length < 2;

  const slider = $('level-slider');
  slider.max = String(bake.levels.length - 1);
  slider.value = String(Math.min(bake.levels.length - 1, 1));
  await loadLevels();
  await showLevel(Number(slider.value));
  buildCrowd();
}

// The crowd plays this many of a bake's clips at most, from the views' clip on.
const kCrowdClips = 3;

// Every level's glTF export of one clip, parsed (null where it failed).
async function loadClipGltfs(clip) {
  const { bake } = state;
  return Promise.all(bake.levels.map((level) =>
    fetchGlb(levelUrl(bake.id, level, clip)).then(parseGlb).catch(() => null)));
}

// Fetches every level's glTF export of the chosen clip (and for the crowd, of the next
// clips). The left view shows the original: the level with all
// joints, else the uploaded file (when it is a glTF binary three.js can read as it is),
// else, for a bake without that level (say levels 15,10,5) opened from the list, the
// finest level baked, which the caption and the note then say.
async function loadLevels() {
  const { bake } = state;
  const allJoints = state.character.joints;
  $('compare-note').textContent = 'loading the levels…';
  state.levelBuffers = await Promise.all(
    bake.levels.map((level) =>
      fetchGlb(levelUrl(bake.id, level, state.clip)).catch((error) => {
        state.exportError = `${error.title}${error.detail ? `: ${error.detail}` : ''}`;
        return null;
      }),
    ),
  );
  // Levels are finest first: the first one exported is the finest there is.
  const finest = state.levelBuffers.findIndex(Boolean);
  const glb = state.localFiles.find((file) => /\.glb$/i.test(file.name));
  if (finest >= 0 && bake.levels[finest].joints === allJoints) {
    state.originalBuffer = state.levelBuffers[finest];
    state.originalJoints = allJoints;
  } else if (glb) {
    state.originalBuffer = await glb.arrayBuffer();
    state.originalJoints = allJoints;
  } else {
    state.originalBuffer = finest >= 0 ? state.levelBuffers[finest] : null;
    state.originalJoints = finest >= 0 ? bake.levels[finest].joints : null;
  }
  state.crowdGltfs = await Promise.all(state.levelBuffers.map((buffer) => (buffer ? parseGlb(buffer) : null)));
  if (!state.crowdGltfs.some(Boolean) && state.originalBuffer) state.crowdGltfs = [await parseGlb(state.originalBuffer)];
  const chosen = Math.max(0, bake.clips.findIndex((clip) => clip.animation === state.clip));
  const crowdClips = [];
  for (let k = 0; k < Math.min(kCrowdClips, bake.clips.length); ++k) crowdClips.push(bake.clips[(chosen + k) % bake.clips.length].animation);
  state.crowdClips = await Promise.all(crowdClips.map(async (name, k) =>
    ({ name, levelGltfs: k === 0 ? state.crowdGltfs : await loadClipGltfs(name) })));
  const notes = [];
  if (state.exportError) notes.push(`Level export unavailable (${state.exportError}); the levels are shown with the original mesh.`);
  if (state.originalJoints !== null && state.originalJoints !== allJoints) {
    notes.push(`This bake has no level with all ${allJoints} joints: the left view shows its finest level, ` +
      `${state.originalJoints} joints, in place of the original.`);
  }
  $('compare-note').textContent = notes.join(' ');
  if (!compare) return;
  if (state.originalBuffer) {
    const original = await parseGlb(state.originalBuffer);
    compare.show(compare.original, original, state.clip, jointCount(original));
    $('caption-original').textContent = state.originalJoints === allJoints
      ? `original: ${allJoints} joints`
      : `finest level baked: ${state.originalJoints} of ${allJoints} joints`;
  } else {
    compare.clear(compare.original);
    $('caption-original').textContent = 'original: not available';
  }
}

async function showLevel(index) {
  const { bake, report } = state;
  state.levelIndex = index;
  const level = bake.levels[index];
  $('level-label').textContent = `${index}: ${level.joints} of ${state.character.joints} joints, ${level.vertices} vertices`;
  for (const cell of document.querySelectorAll('#level-figures td[data-field]')) {
    const field = cell.dataset.field;
    const unit = cell.dataset.unit ? ` ${cell.dataset.unit}` : '';
    let text;
    let value = level[field];
    if (field === 'px_range') {
      value = null;
      text = level.chosen ? pixelRange(level.px_min, level.px_max) : 'never (a coarser level is as accurate)';
    } else if (['joints', 'bytes', 'vertices', 'triangles'].includes(field)) {
      text = `${value}${unit}`;
    } else if (field === 'influences_per_vertex') {
      // Its own influences (at most k, re-solved), or the mesh's merged through the joint map.
      text = `${value === null ? "the mesh's" : `at most ${value}`}, ${format(level.mean_influences, 2)} on average`;
    } else if (field === 'frame_stride') {
      text = value === 1 ? 'every frame' : `every ${value}th frame, interpolated between`;
    } else if (field === 'stream_bytes_per_second') {
      text = `${Math.round(value)}${unit}`;
    } else if (value === null || value === undefined) {
      text = field === 'max_px_for_1px_error' ? 'exact' : '—';
    } else {
      text = `${format(value, field === 'mean_E' ? 6 : 3)}${unit}`;
    }
    cell.textContent = text;
    // The exact figure, as the daemon sent it (the end-to-end test compares these).
    cell.dataset.value = value === null || value === undefined ? '' : String(value);
  }
  const removed = new Set(report.levels[index]?.removed || []);
  for (const row of document.querySelectorAll('#ranking tbody tr')) {
    row.classList.toggle('removed', removed.has(row.dataset.joint));
  }
  drawBakeCurves();

  const buffer = state.levelBuffers[index] || state.originalBuffer;
  if (!compare || !buffer) return;
  const gltf = await parseGlb(buffer);
  if (state.levelIndex === index) {
    compare.show(compare.level, gltf, state.clip, jointCount(gltf));
    $('caption-level').textContent = `level ${index}: ${level.joints} joints, ${level.vertices} vertices`;
  }
}

// The views and the crowd play another clip of the bake: its levels' exports.
async function showClip(name) {
  if (!state.bake || name === state.clip) return;
  state.clip = name;
  await loadLevels();
  await showLevel(state.levelIndex);
  buildCrowd();
}

// ---- 4. Curves and priorities -------------------------------------------------------

let otherBakes = [];

function drawBakeCurves() {
  const { bake, report } = state;
  if (!bake) return;
  const series = [];
  const seen = new Set();
  const add = (variant, levels, meanKey, baselineKey) => {
    if (seen.has(variant)) return;
    seen.add(variant);
    const colour = seen.size - 1;
    series.push({ label: variant, colour, points: levels.map((l) => ({ joints: l.joints, value: l[meanKey] })) });
    if (!baselineKey) return;
    series.push({ label: `${variant} unoptimised`, colour, dashed: true, points: levels.map((l) => ({ joints: l.joints, value: l[baselineKey] })) });
  };
  add(bake.variant, report.levels, 'mean_E', 'baseline_mean_E');
  // `motionlod bake --curves` reports: every variant's points.
  for (const [variant, points] of Object.entries(report.variant_curves || {})) {
    add(variant, points, 'mean_E', 'baseline_mean_E');
  }
  // Other succeeded bakes of the same character and clips: more variants on one plot.
  const clipsOf = (b) => b.clips.map((clip) => clip.motion).join();
  for (const other of otherBakes) {
    if (clipsOf(other) !== clipsOf(bake) || other.state !== 'succeeded' || !other.levels.length) continue;
    add(other.variant, other.levels, 'mean_E', null);
  }
  drawCurves($('error-curve'), series, bake.levels[state.levelIndex]?.joints ?? null);
}

function fillRanking() {
  const body = $('ranking').querySelector('tbody');
  body.replaceChildren();
  for (const joint of state.report.ranking || []) {
    const row = document.createElement('tr');
    row.dataset.joint = joint.joint;
    for (const text of [
      joint.rank,
      joint.joint,
      format(joint.hierarchical, 3),
      format(joint.rotational, 3),
      joint.priority === null ? (joint.removable ? '—' : 'kept') : format(joint.priority, 4),
    ]) {
      const cell = document.createElement('td');
      cell.textContent = String(text);
      row.append(cell);
    }
    body.append(row);
  }
}

// ---- 5. Crowd ---------------------------------------------------------------------------

function buildCrowd() {
  if (!crowd || !state.bake) return;
  crowd.build({
    levels: state.bake.levels,
    clips: state.crowdClips,
    count: Math.max(10, Math.min(1000, Number($('crowd-count').value) || 300)),
    colourByLevel: $('crowd-colour').checked,
  });
  const legend = $('crowd-legend');
  legend.replaceChildren();
  for (const level of state.bake.levels) {
    const count = crowd.counts.get(level.index) || 0;
    const item = document.createElement('span');
    item.dataset.level = String(level.index);
    item.dataset.count = String(count);
    // A style property set from script, not a style attribute: the page's policy allows no
    // inline styles (docs/WEB.md).
    const swatch = document.createElement('i');
    swatch.style.background = kLevelColours[level.index % kLevelColours.length];
    item.append(swatch, `${level.joints} joints: ${count}`);
    legend.append(item);
  }
}

// ---- Wiring -----------------------------------------------------------------------------

async function listBakes() {
  try {
    const { bakes } = await getJson('/v1/bakes');
    otherBakes = state.bake ? bakes.filter((b) => b.character === state.bake.character && b.id !== state.bake.id) : [];
    const select = $('bake-list');
    const chosen = state.bake?.id || '';
    select.replaceChildren(new Option(bakes.length ? '(choose)' : '(none yet)', ''));
    for (const b of bakes) {
      const clips = b.clips.length > 1 ? `${b.clips.length} clips` : b.animation;
      select.append(new Option(`${clips} · ${b.variant} · ${b.state} · ${b.id.slice(0, 8)}`, b.id, false, b.id === chosen));
    }
  } catch (error) {
    showError(error, 'Listing the bakes: ');
  }
}

function wire() {
  $('api-key').addEventListener('change', (event) => {
    setApiKey(event.target.value);
    sessionStorage.setItem('motionlod-key', event.target.value);
    listBakes();
  });
  const stored = sessionStorage.getItem('motionlod-key');
  if (stored) {
    $('api-key').value = stored;
    setApiKey(stored);
  }
  const zone = $('drop-zone');
  zone.addEventListener('dragover', (event) => {
    event.preventDefault();
    zone.classList.add('over');
  });
  zone.addEventListener('dragleave', () => zone.classList.remove('over'));
  zone.addEventListener('drop', (event) => {
    event.preventDefault();
    zone.classList.remove('over');
    upload([...event.dataTransfer.files]);
  });
  $('file-input').addEventListener('change', (event) => upload([...event.target.files]));
  $('motion-input').addEventListener('change', (event) => addMotion(event.target.files[0]));
  $('bake-button').addEventListener('click', bake);
  $('bake-list').addEventListener('change', (event) => {
    if (event.target.value) openBake(event.target.value).catch((error) => showError(error, 'Opening the bake: '));
  });
  $('level-slider').addEventListener('input', (event) => {
    showLevel(Number(event.target.value)).catch((error) => showError(error, 'Level: '));
  });
  $('clip').addEventListener('change', (event) => {
    showClip(event.target.value).catch((error) => showError(error, 'Clip: '));
  });
  $('crowd-count').addEventListener('change', buildCrowd);
  $('crowd-colour').addEventListener('change', buildCrowd);
}

function animate() {
  compare?.tick();
  crowd?.tick();
  requestAnimationFrame(animate);
}

wire();
listBakes().then(() => {
  const match = /bake=([0-9a-f]{64})/.exec(window.location.hash);
  if (match) openBake(match[1]).catch((error) => showError(error, 'Opening the bake: '));
});
requestAnimationFrame(animate);
