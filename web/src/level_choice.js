// The level choice of proto/level_selection.h (SelectLevel), in the page: the crowd picks
// each character's level with it, and it must agree with the daemon's
// GET /v1/bakes/{id}/level?px= (tests/web/level_choice_test.mjs and the end-to-end test
// check that it does). The same arithmetic in doubles as the C++, so the choice agrees
// at the range bounds too. No imports: node runs the test on this file as it is.

// Tallest on-screen height (px) at which a level with this maximum vertex error (a fraction
// of the character's height) stays within `budgetPx`; Infinity when exact.
export function maxPixelHeightForBudget(maxVertexErrorFraction, budgetPx) {
  if (!(maxVertexErrorFraction > 0)) return Infinity;
  return budgetPx / maxVertexErrorFraction;
}

// The index of the level for a character `px` pixels tall. `levels`: the bake's level
// table (GET /v1/bakes/{id}), finest first. The coarsest level within the budget there;
// when none is (taller than every level's limit), the coarsest of the most accurate
// levels. A coarser level may be exact or more accurate than a finer one: the rule does
// not assume that errors grow as levels get coarser.
export function selectLevel(levels, px, budgetPx = 1) {
  const limits = levels.map((level) => maxPixelHeightForBudget(level.max_vertex_error_pct / 100, budgetPx));
  const largestLimit = limits.reduce((largest, limit) => (largest < limit ? limit : largest), 0);
  // Taller than every limit (or NaN): as if at the largest limit.
  const height = px < largestLimit ? px : largestLimit;
  for (let l = levels.length - 1; l > 0; --l) {
    if (limits[l] >= height) return l;
  }
  return 0;
}

// The level entry `selectLevel` picks.
export function levelForPixels(levels, px, budgetPx = 1) {
  return levels[selectLevel(levels, px, budgetPx)];
}
