#include "proto/level_selection.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace motionlod::proto {
namespace {

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

}  // namespace
}  // namespace motionlod::proto
