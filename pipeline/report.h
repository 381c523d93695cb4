// report.json: what a bake produced and how good it is. Field names and units are
// documented in docs/report.md.
#pragma once

#include <array>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/character.h"
#include "core/motion.h"
#include "core/rank_joints.h"
#include "core/solve_levels.h"
#include "pipeline/bake.h"
#include "pipeline/cost_levels.h"
#include "proto/level_format.h"

namespace motionlod::pipeline {

inline constexpr int kReportVersion = 1;

struct CurvePoint {
  int joints = 0;
  double mean_e = 0;
  double baseline_mean_e = 0;
  double max_vertex_error_pct = 0;
};
struct VariantCurve {
  core::Variant variant;
  std::vector<CurvePoint> points;  // every level, finest first
};

// One level as a bake writes it: what the file holds, and its skeleton's solve on the whole
// mesh (the E and baseline figures of the report).
struct BakedLevel {
  CostLevel level;
  const core::LevelResult* skeleton = nullptr;
};

struct ReportInputs {
  const BakeRequest& request;
  const core::Character& character;
  const core::Motion& motion;
  const core::JointRanking& ranking;        // the one the levels follow (request.ranking_method)
  const core::JointRanking& paper_ranking;  // the paper's, for the table beside it
  const core::PreparedMotion& prepared;
  const std::vector<BakedLevel>& levels;  // finest first
  const std::vector<VariantCurve>& curves;
  double bake_seconds = 0;
  double skinning_pass_seconds = 0;
  int threads = 1;
  std::vector<std::string> warnings;
};

// The level file of `levels` (finest first): header and skeleton from the character, motion
// and settings, each level's kept joints, joint map, figures (its deviation), pose rate,
// own mesh and influences where it has them, cost and stored matrices, read in place:
// encoding copies them once, straight into the file. `run`: where the encoding's checks
// run (proto::EncodeLevelSet).
StatusOr<std::string> EncodeBakedLevels(const core::Character& character,
                                        const core::Motion& motion,
                                        const core::SolveSettings& settings,
                                        const std::array<uint8_t, 32>& source_hash,
                                        const std::vector<BakedLevel>& levels,
                                        const PieceRunner& run);

nlohmann::json BuildReport(const ReportInputs& inputs);

// The removal order `ranking` (made by `method`) as JSON rows, first removed first, each
// with the greedy removal's error (null for the paper's order) and the paper's rank and
// priority (fig. 2) from `paper`.
nlohmann::json RankingTable(const core::Character& character, core::RankingMethod method,
                            const core::JointRanking& ranking, const core::JointRanking& paper);

}  // namespace motionlod::pipeline
