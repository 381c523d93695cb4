// Builds the viewer into web/dist (served by motionlodd at "/"). `npm run dev` serves it
// with hot reload and forwards the API to a daemon on :8080.
import { defineConfig } from 'vite';

export default defineConfig({
  base: './',
  build: {
    outDir: 'dist',
    emptyOutDir: true,
    // three.js alone is about 700 KB minified; one chunk is simplest to serve.
    chunkSizeWarningLimit: 1500,
  },
  server: {
    proxy: { '/v1': 'http://127.0.0.1:8080' },
  },
});
