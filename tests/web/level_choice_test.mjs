// The viewer's level choice (web/src/level_choice.js) against the rule of
// proto/level_selection.h, on the tables of tests/proto/level_selection_test.cc: the same
// cases give the same levels. The end-to-end test (viewer_e2e.mjs) checks it against the
// daemon's own choice on real bakes.
import assert from 'node:assert/strict';
import test from 'node:test';
import { levelForPixels, maxPixelHeightForBudget, selectLevel } from '../../web/src/level_choice.js';

// A level table as GET /v1/bakes/{id} gives it, from errors as fractions of the height.
const table = (fractions) => fractions.map((fraction, index) => ({ index, max_vertex_error_pct: fraction * 100 }));

test('the coarsest level within the budget', () => {
  const levels = table([0.0, 0.001, 0.004, 0.02]);
  assert.equal(maxPixelHeightForBudget(0.004, 1), 250);
  assert.equal(maxPixelHeightForBudget(0, 1), Infinity);
  assert.equal(selectLevel(levels, 30), 3);
  assert.equal(selectLevel(levels, 100), 2);
  assert.equal(selectLevel(levels, 250), 2); // exactly on the budget
  assert.equal(selectLevel(levels, 251), 1);
  assert.equal(selectLevel(levels, 5000), 0);
  assert.equal(selectLevel(levels, 1000, 4), 2); // a larger budget allows coarser
  assert.equal(levelForPixels(levels, 100), levels[2]);
});

test('an exact coarser level serves every large height; the full one is never chosen', () => {
  const levels = table([0.0, 0.0, 0.001, 0.01]);
  assert.equal(selectLevel(levels, 20), 3);
  assert.equal(selectLevel(levels, 1000), 2);
  assert.equal(selectLevel(levels, 1001), 1);
  assert.equal(selectLevel(levels, 1e9), 1);
  assert.equal(selectLevel(levels, Infinity), 1);
});

test('a more accurate coarser level hides the finer ones', () => {
  const levels = table([0.002, 0.004, 0.001, 0.01]);
  assert.equal(selectLevel(levels, 50), 3);
  assert.equal(selectLevel(levels, 300), 2);
  assert.equal(selectLevel(levels, 5000), 2);
});

test('above every limit the most accurate level, the coarser of equals', () => {
  assert.equal(selectLevel(table([0.001, 0.002]), 1e6), 0);
  assert.equal(selectLevel(table([0.001, 0.002]), NaN), 0);
  const tied = table([0.001, 0.001, 0.002]);
  assert.equal(selectLevel(tied, 1e6), 1);
  assert.equal(selectLevel(tied, 600), 1);
  assert.equal(selectLevel(tied, 400), 2);
  assert.equal(selectLevel(table([0.05]), 1000), 0);
});

test('on random tables the choice only gets finer as the height grows, and is within the budget when any level is', () => {
  let seed = 43;
  const random = () => ((seed = (seed * 1103515245 + 12345) % 2147483648) / 2147483648);
  for (let k = 0; k < 500; ++k) {
    const levels = table(Array.from({ length: 1 + Math.floor(random() * 8) }, () => Math.floor(random() * 6) * 0.0037));
    const limits = levels.map((level) => maxPixelHeightForBudget(level.max_vertex_error_pct / 100, 1));
    let previous = levels.length - 1;
    for (let px = 0.5; px < 1e5; px *= 1.1) {
      const l = selectLevel(levels, px);
      assert.ok(l <= previous, `table ${k}: ${px} px picks ${l}, coarser than ${previous} below`);
      previous = l;
      const within = limits.map((limit, index) => (px <= limit ? index : -1)).filter((index) => index >= 0);
      if (within.length) assert.equal(l, Math.max(...within), `table ${k}, ${px} px`);
      else assert.equal(l, limits.lastIndexOf(Math.max(...limits)), `table ${k}, ${px} px: not the coarsest most accurate`);
    }
  }
});
