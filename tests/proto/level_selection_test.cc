#include "proto/level_selection.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

namespace motionlod::proto {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(LevelSelection, PixelHeightFollowsFigure5) {
  // s = 2, d = 10, fov 60 degrees, H = 1080: theta = atan(0.2) = 0.19740 rad,
  // x = 0.19740 / 1.04720 * 1080 = 203.58 px.
  const CameraView view{std::numbers::pi / 3, 10.0, 2.0, 1080.0};
  EXPECT_NEAR(PixelHeight(view), 203.58, 0.01);
  EXPECT_EQ(PixelHeight({0, 10, 2, 1080}), 0.0);
  EXPECT_EQ(PixelHeight({std::numbers::pi / 3, -1, 2, 1080}), 0.0);
}

TEST(LevelSelection, PicksTheCoarsestLevelWithinTheBudget) {
  // Errors as fractions of the height, finest first.
  const double errors[] = {0.0, 0.001, 0.004, 0.02};
  EXPECT_EQ(MaxPixelHeightForBudget(0.004, 1.0), 250.0);
  EXPECT_TRUE(std::isinf(MaxPixelHeightForBudget(0.0, 1.0)));
  EXPECT_EQ(SelectLevel(errors, 30.0, 1.0), 3);    // 0.6 px at the coarsest
  EXPECT_EQ(SelectLevel(errors, 100.0, 1.0), 2);   // coarsest: 2 px, next: 0.4 px
  EXPECT_EQ(SelectLevel(errors, 250.0, 1.0), 2);   // exactly on the budget
  EXPECT_EQ(SelectLevel(errors, 251.0, 1.0), 1);
  EXPECT_EQ(SelectLevel(errors, 5000.0, 1.0), 0);
  EXPECT_EQ(SelectLevel(errors, 1000.0, 4.0), 2);  // a larger budget allows coarser
}

// The ranges of the chosen levels, checked to partition (0, +inf) from the coarsest up.
void ExpectPartition(const std::vector<LevelRange>& ranges) {
  double covered = 0;
  int chosen = 0;
  for (size_t l = ranges.size(); l-- > 0;) {
    const LevelRange& range = ranges[l];
    if (!range.chosen) {
      EXPECT_EQ(range.px_min, 0.0) << "level " << l;
      EXPECT_EQ(range.px_max, 0.0) << "level " << l;
      continue;
    }
    ++chosen;
    EXPECT_EQ(range.px_min, covered) << "level " << l << ": a gap or an overlap";
    EXPECT_LT(range.px_min, range.px_max) << "level " << l << ": an empty range";
    covered = range.px_max;
  }
  EXPECT_GT(chosen, 0);
  EXPECT_EQ(covered, kInf) << "the finest chosen level serves every taller character";
}

// SelectLevel picks, at each height, the level whose range holds it: at and around every
// bound (the next double either side) and between them.
void ExpectSelectionMatchesRanges(const std::vector<double>& errors, double budget_px) {
  const std::vector<LevelRange> ranges = LevelRanges(errors, budget_px);
  ExpectPartition(ranges);
  std::vector<double> heights = {1e-9, 0.5, 1e7, kInf};
  for (const LevelRange& range : ranges) {
    if (!range.chosen || std::isinf(range.px_max)) continue;
    heights.push_back(range.px_max);
    heights.push_back(std::nextafter(range.px_max, 0.0));
    heights.push_back(std::nextafter(range.px_max, kInf));
    heights.push_back(range.px_max * 0.75);
  }
  for (double px : heights) {
    const int l = SelectLevel(errors, px, budget_px);
    ASSERT_GE(l, 0);
    ASSERT_LT(l, static_cast<int>(ranges.size()));
    EXPECT_TRUE(ranges[l].chosen) << px << " px";
    EXPECT_GT(px, ranges[l].px_min) << px << " px picks level " << l;
    EXPECT_LE(px, ranges[l].px_max) << px << " px picks level " << l;
  }
}

TEST(LevelSelection, RangesOfMonotoneErrorsFollowTheLimits) {
  const std::vector<double> errors = {0.0, 0.001, 0.004, 0.02};  // limits inf, 1000, 250, 50
  const std::vector<LevelRange> ranges = LevelRanges(errors, 1.0);
  ASSERT_EQ(ranges.size(), 4u);
  EXPECT_TRUE(ranges[3].chosen);
  EXPECT_EQ(ranges[3].px_min, 0.0);
  EXPECT_EQ(ranges[3].px_max, 50.0);
  EXPECT_EQ(ranges[2].px_min, 50.0);
  EXPECT_EQ(ranges[2].px_max, 250.0);
  EXPECT_EQ(ranges[1].px_min, 250.0);
  EXPECT_EQ(ranges[1].px_max, 1000.0);
  EXPECT_EQ(ranges[0].px_min, 1000.0);
  EXPECT_EQ(ranges[0].px_max, kInf);
  ExpectSelectionMatchesRanges(errors, 1.0);
}

TEST(LevelSelection, AnExactCoarserLevelServesEveryLargeHeight) {
  // Level 1 drops only joints that move no vertex (pole targets): exact like level 0, which
  // is then never worth its cost.
  const std::vector<double> errors = {0.0, 0.0, 0.001, 0.01};  // limits inf, inf, 1000, 100
  const std::vector<LevelRange> ranges = LevelRanges(errors, 1.0);
  EXPECT_FALSE(ranges[0].chosen);
  EXPECT_TRUE(ranges[1].chosen);
  EXPECT_EQ(ranges[1].px_min, 1000.0);
  EXPECT_EQ(ranges[1].px_max, kInf);
  EXPECT_EQ(SelectLevel(errors, 20.0, 1.0), 3);
  EXPECT_EQ(SelectLevel(errors, 1000.0, 1.0), 2);
  EXPECT_EQ(SelectLevel(errors, 1001.0, 1.0), 1);
  EXPECT_EQ(SelectLevel(errors, 1e9, 1.0), 1);
  EXPECT_EQ(SelectLevel(errors, kInf, 1.0), 1);
  ExpectSelectionMatchesRanges(errors, 1.0);
}

TEST(LevelSelection, AMoreAccurateCoarserLevelHidesTheFinerOnes) {
  // Level 2 is more accurate than levels 0 and 1 (limits 500, 250, 1000, 100): above 100 px
  // it serves every height, the finer ones never (none is exact: above 1000 px level 2
  // exceeds the budget least).
  const std::vector<double> errors = {0.002, 0.004, 0.001, 0.01};
  const std::vector<LevelRange> ranges = LevelRanges(errors, 1.0);
  EXPECT_FALSE(ranges[0].chosen);
  EXPECT_FALSE(ranges[1].chosen);
  EXPECT_EQ(ranges[2].px_min, 100.0);
  EXPECT_EQ(ranges[2].px_max, kInf);
  EXPECT_EQ(ranges[3].px_max, 100.0);
  EXPECT_EQ(SelectLevel(errors, 50.0, 1.0), 3);
  EXPECT_EQ(SelectLevel(errors, 300.0, 1.0), 2);
  EXPECT_EQ(SelectLevel(errors, 5000.0, 1.0), 2);
  ExpectSelectionMatchesRanges(errors, 1.0);
}

TEST(LevelSelection, AboveEveryLimitTheMostAccurateLevelServes) {
  // No exact level: past the finest level's limit nothing is within the budget and the
  // finest, the most accurate, is the best there is.
  EXPECT_EQ(SelectLevel(std::vector<double>{0.001, 0.002}, 1e6, 1.0), 0);
  EXPECT_EQ(SelectLevel(std::vector<double>{0.001, 0.002}, std::nan(""), 1.0), 0);
  // Equal errors: the coarser of the two, at every height (it costs less).
  const std::vector<double> tied = {0.001, 0.001, 0.002};
  EXPECT_EQ(SelectLevel(tied, 1e6, 1.0), 1);
  EXPECT_EQ(SelectLevel(tied, 600.0, 1.0), 1);
  EXPECT_EQ(SelectLevel(tied, 400.0, 1.0), 2);
  EXPECT_FALSE(LevelRanges(tied, 1.0)[0].chosen);
  ExpectSelectionMatchesRanges(tied, 1.0);
}

TEST(LevelSelection, OneLevelServesEveryHeight) {
  const std::vector<LevelRange> ranges = LevelRanges(std::vector<double>{0.05}, 1.0);
  ASSERT_EQ(ranges.size(), 1u);
  EXPECT_TRUE(ranges[0].chosen);
  EXPECT_EQ(ranges[0].px_min, 0.0);
  EXPECT_EQ(ranges[0].px_max, kInf);
  EXPECT_EQ(SelectLevel(std::vector<double>{0.05}, 1000.0, 1.0), 0);
}

TEST(LevelSelection, RangesAndSelectionAgreeOnRandomTables) {
  // Errors in any order, with repeats and exact levels, and budgets other than 1 px.
  std::mt19937 random(43);
  std::uniform_int_distribution<int> count(1, 8);
  std::uniform_int_distribution<int> step(0, 5);
  for (int table = 0; table < 500; ++table) {
    std::vector<double> errors(static_cast<size_t>(count(random)));
    for (double& error : errors) error = step(random) * 0.0037;
    const double budget_px = table % 3 == 0 ? 1.0 : 0.5 + table % 7;
    SCOPED_TRACE("table " + std::to_string(table));
    ExpectSelectionMatchesRanges(errors, budget_px);
  }
}

}  // namespace
}  // namespace motionlod::proto
