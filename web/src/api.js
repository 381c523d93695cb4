// The motionlodd /v1 API as the viewer uses it. Every failure is an ApiError carrying
// the daemon's RFC 9457 problem (title, status, detail) when it sent one.

export class ApiError extends Error {
  constructor(status, title, detail) {
    super(detail || title || `HTTP ${status}`);
    this.status = status;
    this.title = title || `HTTP ${status}`;
    this.detail = detail || '';
  }
}

let apiKey = '';
export function setApiKey(key) {
  apiKey = key.trim();
}
export function authHeaders() {
  return apiKey ? { Authorization: `Bearer ${apiKey}` } : {};
}

async function problemOf(response) {
  let title = response.statusText;
  let detail = '';
  const type = response.headers.get('content-type') || '';
  if (type.includes('json')) {
    const body = await response.json().catch(() => null);
    if (body) {
      title = body.title || title;
      detail = body.detail || '';
    }
  }
  return new ApiError(response.status, title, detail);
}

export async function getJson(path) {
  let response;
  try {
    response = await fetch(path, { headers: { Accept: 'application/json', ...authHeaders() } });
  } catch (error) {
    throw new ApiError(0, 'network error', `the daemon did not answer ${path} (${error.message})`);
  }
  if (!response.ok) throw await problemOf(response);
  return response.json();
}

export async function postJson(path, body) {
  const response = await fetch(path, {
    method: 'POST',
    headers: { 'Content-Type': 'application/json', Accept: 'application/json', ...authHeaders() },
    body: JSON.stringify(body),
  });
  if (!response.ok) throw await problemOf(response);
  return response.json();
}

// Uploads files with upload progress (XMLHttpRequest: fetch reports none). One file goes
// as the raw body named by X-Filename; several (a .gltf with its .bin) as multipart
// parts, the model file in the field "file".
export function uploadFiles(path, files, onProgress) {
  const modelPattern = /\.(glb|gltf|fbx|dae|bvh|x|smd)$/i;
  return new Promise((resolve, reject) => {
    const request = new XMLHttpRequest();
    request.open('POST', path);
    for (const [name, value] of Object.entries(authHeaders())) request.setRequestHeader(name, value);
    request.setRequestHeader('Accept', 'application/json');
    request.upload.onprogress = (event) => {
      if (event.lengthComputable) onProgress(event.loaded / event.total);
    };
    request.onerror = () => reject(new ApiError(0, 'network error', 'the upload did not reach the daemon'));
    request.onload = () => {
      let body = null;
      try {
        body = JSON.parse(request.responseText);
      } catch {
        body = null;
      }
      if (request.status >= 200 && request.status < 300 && body) return resolve(body);
      reject(new ApiError(request.status, body?.title || request.statusText, body?.detail || ''));
    };
    if (files.length === 1) {
      request.setRequestHeader('Content-Type', 'application/octet-stream');
      request.setRequestHeader('X-Filename', files[0].name);
      request.send(files[0]);
      return;
    }
    const form = new FormData();
    const main = files.find((file) => modelPattern.test(file.name));
    for (const file of files) form.append(file === main ? 'file' : 'part', file, file.name);
    request.send(form);
  });
}

// Long-polls GET /v1/jobs/{id}?wait= until the job has finished, reporting each change.
// (EventSource, the SSE stream, cannot send an API key.)
export async function waitForJob(id, onStatus) {
  let status = await getJson(`/v1/jobs/${id}`);
  onStatus(status);
  while (status.state !== 'succeeded' && status.state !== 'failed') {
    try {
      status = await getJson(`/v1/jobs/${id}?wait=20&after=${status.version}`);
    } catch (error) {
      // Too many open long-polls (503): wait a moment and ask again.
      if (error.status !== 503) throw error;
      await new Promise((resolve) => setTimeout(resolve, 1000));
      continue;
    }
    onStatus(status);
  }
  return status;
}
