// The crowd runtime benchmark (the paper's fig. 8 and 9, on the CPU): N characters on a
// ground plane in front of a fixed camera, spread uniformly over the area of a 60 degree
// wedge from 2 m to 100 m (fig. 9's layout: many far, few near). Each frame every
// character gets its on-screen height from the camera (proto/level_selection.h, fig. 5),
// picks its level with the client's LevelSelector (1 px budget, 10% hysteresis) and is
// drawn by the client: PlayFrame (the level's matrices, interpolated where it stores fewer
// poses) and SkinFrameJob over the level's own vertices and influences (client/skinner.h).
// Beside it the same crowd at full detail (level 0: every joint, vertex and influence,
// every frame). The characters are the skinned, animated files of ../shared/data, baked
// in-process with pipeline::Bake (the default ladder, levels by cost, vpno+pd), and again
// with each part of a level's saving switched off (joints, vertices, influences, pose rate:
// BakeRequest::level_parts) to give each part's share.
//
// Per frame, timed in the worker's CPU time (CLOCK_THREAD_CPUTIME_ID: time the thread ran,
// so other processes on a shared machine do not inflate it; the frame's wall time is
// reported beside it), and split between three phases as the steady clock times them per
// character (reading the thread's CPU clock costs about a microsecond, which per character
// would add 3 ms a frame to both crowds):
//   matrix update  level choice, then PlayFrame into the frame's matrix stream (what a GPU
//                  renderer uploads: 48 m bytes)
//   skinning       SkinFrameJob: positions and normals of the level's vertices into a
//                  scratch buffer of the worker (cache-resident)
//   output         the scratch copied into the crowd's vertex buffer (24 bytes per
//                  vertex: what a renderer hands to the GPU)
// Quality (a separate, untimed pass on every 10th frame): each character drawn at its
// level and at full detail; the error in pixels of every original vertex is its distance
// to the point of the level's surface that stands for it (the vertex itself, or a point of
// a simplified triangle: core::SurfaceCorrespondence), scaled by the character's on-screen
// height over its model height (the units of the level table); mean and max over every
// vertex of every character.
//
// The crowds run alternately, --repetitions times per thread count; the tables give the
// median of each figure.
//
//   crowd [--characters=1000] [--frames=120] [--threads=1,2] [--repetitions=3] [--data=DIR]
//         [--budget=1] [--hysteresis=0.1] [--parts=1] [--heights=800,400,...]
//         [--json=FILE]
#include <time.h>

#include <algorithm>
#include <array>
#include <barrier>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Dense>
#include <nlohmann/json.hpp>

#include "client/level_selector.h"
#include "client/skinner.h"
#include "core/simplify_mesh.h"
#include "io/asset.h"
#include "pipeline/bake.h"
#include "proto/level_format.h"
#include "proto/level_selection.h"

namespace motionlod::bench {
namespace {

namespace fs = std::filesystem;
using client::LevelSelector;
using client::LevelSkin;
using client::SkinFrameJob;
using client::SkinMesh;
using Clock = std::chrono::steady_clock;

constexpr double kFovY = std::numbers::pi / 3;  // 60 degrees
constexpr double kScreenHeightPx = 1080;
constexpr double kCharacterSizeM = 1.8;  // every character drawn 1.8 m tall
constexpr double kNearM = 2, kFarM = 100;
constexpr int kQualityEvery = 10;  // frames between quality samples

struct Options {
  int characters = 1000;
  int frames = 120;
  std::vector<int> threads = {1, 2};
  int repetitions = 3;
  fs::path data = MOTIONLOD_BENCH_DATA;
  double budget_px = 1.0;
  double hysteresis = 0.1;
  bool parts = true;  // also the ladders with each part switched off
  std::vector<double> heights_px;  // the ladder's heights; empty: the bake's default
  std::string json_path;
};

// One bake of a kind of character: its levels as the client draws them.
struct Ladder {
  std::string name;  // which parts its levels cut
  proto::AlignedBytes level_set_bytes;
  proto::LevelSetView level_set;
  std::vector<LevelSkin> skins;  // per level
  // Per level: each original vertex's point on the level's surface (empty where the level
  // draws every vertex).
  std::vector<std::vector<core::SurfacePoint>> correspondence;
  std::optional<LevelSelector> selector;
};

// One kind of character: its mesh and its ladders (the first cuts every part).
struct CharacterType {
  std::string label;
  std::shared_ptr<const core::Character> character;
  SkinMesh mesh;
  std::vector<Ladder> ladders;
  double height = 0;  // model units
};

// The ladders baked per character: every part, then each part switched off.
struct LadderKind {
  const char* name;
  pipeline::CostLevelParts parts;
};
constexpr LadderKind kLadderKinds[] = {
    {"every part", {}},
    {"no joint cut", {.joints = false}},
    {"no vertex cut", {.vertices = false}},
    {"no influence cut", {.influences = false}},
    {"no pose-rate cut", {.pose_rate = false}},
};

struct Instance {
  int type = 0;
  double distance_m = 0;
  int phase = 0;             // frame offset into the motion
  int level = -1;            // current level (hysteresis state)
  size_t vertex_offset = 0;  // into the crowd's vertex buffer, in vertices
};

// Frame `frame` of a character whose motion starts at `phase`: the clip and the frame
// within it, over every clip of the set one after another.
std::pair<uint32_t, uint32_t> ClipFrame(const proto::LevelSetView& set, int frame, int phase) {
  const uint32_t g = static_cast<uint32_t>(frame + phase) % set.frame_count();
  for (uint32_t c = 0; c < set.clip_count(); ++c) {
    const proto::ClipView& clip = set.clip(c);
    if (g < clip.first_frame + clip.frame_count) return {c, g - clip.first_frame};
  }
  return {0, 0};
}

bool ParseOptions(int argc, char** argv, Options& o) {
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    const size_t eq = arg.find('=');
    const std::string name = arg.substr(0, eq),
                      value = eq == std::string::npos ? "" : arg.substr(eq + 1);
    if (name == "--characters") {
      o.characters = std::stoi(value);
    } else if (name == "--frames") {
      o.frames = std::stoi(value);
    } else if (name == "--threads") {
      o.threads.clear();
      std::stringstream list(value);
      for (std::string item; std::getline(list, item, ',');) o.threads.push_back(std::stoi(item));
    } else if (name == "--repetitions") {
      o.repetitions = std::stoi(value);
    } else if (name == "--data") {
      o.data = value;
    } else if (name == "--budget") {
      o.budget_px = std::stod(value);
    } else if (name == "--hysteresis") {
      o.hysteresis = std::stod(value);
    } else if (name == "--parts") {
      o.parts = value != "0";
    } else if (name == "--heights") {
      std::stringstream list(value);
      for (std::string item; std::getline(list, item, ',');) o.heights_px.push_back(std::stod(item));
    } else if (name == "--json") {
      o.json_path = value;
    } else {
      std::fprintf(stderr, "crowd: unknown argument '%s'\n", arg.c_str());
      return false;
    }
  }
  const bool threads_ok = !o.threads.empty() && std::all_of(o.threads.begin(), o.threads.end(),
                                                            [](int t) { return t >= 1; });
  if (o.characters < 1 || o.frames < 1 || o.repetitions < 1 || !threads_ok || !(o.budget_px > 0)) {
    std::fprintf(stderr,
                 "crowd: --characters, --frames, --threads, --repetitions and --budget must be "
                 "positive\n");
    return false;
  }
  return true;
}

bool RigidFullDetailMisses(std::string_view level_set) {
  auto view = proto::DecodeLevelSet(level_set);
  return view.ok() && view->level(0).figures().max_vertex_error_pct > pipeline::kRigidMissPct;
}

std::optional<CharacterType> LoadType(const fs::path& path, const Options& o) {
  auto asset = io::LoadAssetFile(path);
  if (!asset.ok() || (*asset)->animations().empty() || (*asset)->has_proxy_skin()) {
    std::fprintf(stderr, "crowd: skipping %s: %s\n", path.filename().c_str(),
                 asset.ok() ? "no animation or no skin" : asset.status().ToString().c_str());
    return std::nullopt;
  }
  pipeline::BakeRequest request;
  request.character = *asset;
  request.threads = 2;
  request.measure_skinning_pass = false;
  request.ladder_heights_px = o.heights_px;
  auto inputs = pipeline::PrepareInputs(request);
  if (!inputs.ok()) {
    std::fprintf(stderr, "crowd: skipping %s: %s\n", path.filename().c_str(),
                 inputs.status().ToString().c_str());
    return std::nullopt;
  }
  CharacterType type;
  type.label = path.filename().string();
  type.character = inputs->character;
  type.height = type.character->height();
  const core::RawSkin& skin = type.character->skin();
  const size_t p = skin.positions.size();
  type.mesh = SkinMesh{{skin.positions.data()->data(), 3 * p},
                       {skin.normals.data()->data(), 3 * p},
                       skin.influence_offsets,
                       skin.influence_joints,
                       skin.influence_weights};
  for (const LadderKind& kind : kLadderKinds) {
    if (!o.parts && &kind != &kLadderKinds[0]) break;
    request.level_parts = kind.parts;
    auto output = pipeline::Bake(request);
    Ladder ladder;
    ladder.name = kind.name;
    // A rigid bake whose full detail is off (the rig scales joints: the bake warns) is
    // baked again in vpno, as the warning advises.
    if (output.ok() && core::IsRigid(request.settings.variant) &&
        RigidFullDetailMisses(output->level_set)) {
      std::fprintf(stderr, "crowd: %s scales joints: baked in vpno\n", type.label.c_str());
      request.settings.variant = core::Variant::kVPNO;
      output = pipeline::Bake(request);
    }
    if (!output.ok()) {
      std::fprintf(stderr, "crowd: skipping %s: %s\n", path.filename().c_str(),
                   output.status().ToString().c_str());
      return std::nullopt;
    }
    ladder.level_set_bytes = proto::AlignedBytes::CopyOf(output->level_set);
    auto view = proto::DecodeLevelSet(ladder.level_set_bytes.bytes());
    if (!view.ok()) return std::nullopt;
    ladder.level_set = std::move(*view);
    std::vector<double> errors;
    for (const proto::LevelView& level : ladder.level_set.levels()) {
      auto built = LevelSkin::Build(type.mesh, level);
      if (!built.ok()) return std::nullopt;
      ladder.skins.push_back(std::move(*built));
      std::vector<core::SurfacePoint> points;
      if (level.has_own_mesh()) {
        std::vector<std::array<uint32_t, 3>> triangles(level.triangles().size() / 3);
        std::memcpy(triangles.data(), level.triangles().data(), level.triangles().size_bytes());
        points = core::SurfaceCorrespondence(*type.character, level.vertices(), triangles);
      }
      ladder.correspondence.push_back(std::move(points));
      errors.push_back(level.figures().max_vertex_error_pct);
    }
    auto selector = LevelSelector::Create(errors, {o.budget_px, o.hysteresis});
    if (!selector.ok()) return std::nullopt;
    ladder.selector = std::move(*selector);
    type.ladders.push_back(std::move(ladder));
  }
  return type;
}

// Seconds of CPU time the calling thread has run.
double ThreadCpuSeconds() {
  timespec now{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

double PixelHeightAt(double distance_m) {
  return proto::PixelHeight({kFovY, distance_m, kCharacterSizeM, kScreenHeightPx});
}

struct Phases {  // CPU seconds
  double matrix_s = 0, skinning_s = 0, output_s = 0;
  double total_s() const { return matrix_s + skinning_s + output_s; }
  uint64_t matrix_bytes = 0;
};

struct RunResult {
  int threads = 0;
  int ladder = -1;          // the ladder drawn, -1: full detail
  double ms_per_frame = 0;  // wall, per frame
  Phases per_frame;         // CPU, summed over threads, per frame
};

// Runs the crowd for o.frames frames on `threads` workers (contiguous slices of the
// crowd, a barrier at every frame's end): every character at full detail (ladder -1) or at
// its level of `ladder`.
RunResult RunCrowd(const std::vector<CharacterType>& types, std::vector<Instance> crowd,
                   std::vector<float>& vertex_buffer, int ladder, int threads, const Options& o) {
  size_t max_vertices = 0, max_kept = 0;
  for (const CharacterType& type : types) {
    max_vertices = std::max<size_t>(max_vertices, type.mesh.positions.size() / 3);
    max_kept = std::max<size_t>(max_kept, type.ladders.front().level_set.joint_count());
  }
  // The frame's matrix stream: a slot of the largest palette per character.
  std::vector<float> stream(crowd.size() * max_kept * proto::kMatrixFloats);
  std::vector<Phases> phases(static_cast<size_t>(threads));
  std::vector<double> frame_seconds;
  Clock::time_point frame_start = Clock::now();
  std::barrier frame_end(threads, [&]() noexcept {
    const Clock::time_point now = Clock::now();
    frame_seconds.push_back(std::chrono::duration<double>(now - frame_start).count());
    frame_start = now;
  });
  auto work = [&](int worker) {
    const size_t begin = crowd.size() * worker / threads,
                 end = crowd.size() * (worker + 1) / threads;
    std::vector<float> scratch_positions(3 * max_vertices), scratch_normals(3 * max_vertices);
    Phases& mine = phases[static_cast<size_t>(worker)];
    for (int frame = 0; frame < o.frames; ++frame) {
      const double cpu_begin = ThreadCpuSeconds();
      Clock::duration matrix{}, skinning{}, output{};
      for (size_t c = begin; c < end; ++c) {
        Instance& instance = crowd[c];
        const CharacterType& type = types[static_cast<size_t>(instance.type)];
        const Ladder& drawn = type.ladders[static_cast<size_t>(std::max(ladder, 0))];
        const Clock::time_point t0 = Clock::now();
        const int level =
            ladder >= 0 ? drawn.selector->Choose(PixelHeightAt(instance.distance_m), instance.level)
                        : 0;
        instance.level = level;
        const proto::LevelView& view = drawn.level_set.level(static_cast<uint32_t>(level));
        const auto [clip, t] = ClipFrame(drawn.level_set, frame, instance.phase);
        const std::span<float> slot(stream.data() + c * max_kept * proto::kMatrixFloats,
                                    view.kept_count() * proto::kMatrixFloats);
        if (!client::PlayFrame(drawn.level_set, view, clip, t, slot).ok()) std::abort();  // a bug
        mine.matrix_bytes += slot.size_bytes();
        const Clock::time_point t1 = Clock::now();
        const LevelSkin& skin = drawn.skins[static_cast<size_t>(level)];
        const size_t floats = 3 * size_t{skin.vertex_count()};
        const SkinFrameJob job{&skin,
                               slot,
                               drawn.level_set.rigid(),
                               {scratch_positions.data(), floats},
                               {scratch_normals.data(), floats}};
        if (!job.Run().ok()) std::abort();  // shapes are fixed at set-up: a bug
        const Clock::time_point t2 = Clock::now();
        float* out = vertex_buffer.data() + instance.vertex_offset * 6;
        std::memcpy(out, scratch_positions.data(), floats * sizeof(float));
        std::memcpy(out + floats, scratch_normals.data(), floats * sizeof(float));
        const Clock::time_point t3 = Clock::now();
        matrix += t1 - t0;
        skinning += t2 - t1;
        output += t3 - t2;
      }
      // The frame's CPU time, split between the phases as their clock times are.
      const double cpu = ThreadCpuSeconds() - cpu_begin;
      const double timed = std::chrono::duration<double>(matrix + skinning + output).count();
      if (timed > 0) {
        mine.matrix_s += cpu * std::chrono::duration<double>(matrix).count() / timed;
        mine.skinning_s += cpu * std::chrono::duration<double>(skinning).count() / timed;
        mine.output_s += cpu * std::chrono::duration<double>(output).count() / timed;
      }
      frame_end.arrive_and_wait();
    }
  };
  frame_start = Clock::now();
  std::vector<std::thread> workers;
  for (int w = 1; w < threads; ++w) workers.emplace_back(work, w);
  work(0);
  for (std::thread& worker : workers) worker.join();

  RunResult result;
  result.threads = threads;
  result.ladder = ladder;
  // The first frame warms caches and the allocator: left out of the mean.
  const size_t skip = frame_seconds.size() > 1 ? 1 : 0;
  double total = 0;
  for (size_t f = skip; f < frame_seconds.size(); ++f) total += frame_seconds[f];
  result.ms_per_frame = 1e3 * total / static_cast<double>(frame_seconds.size() - skip);
  for (const Phases& p : phases) {
    result.per_frame.matrix_s += p.matrix_s / o.frames;
    result.per_frame.skinning_s += p.skinning_s / o.frames;
    result.per_frame.output_s += p.output_s / o.frames;
    result.per_frame.matrix_bytes += p.matrix_bytes / static_cast<uint64_t>(o.frames);
  }
  return result;
}

// The median of each figure over repeated runs (each figure on its own).
RunResult Median(std::vector<RunResult> runs) {
  auto median = [&runs](auto field) {
    std::vector<double> values;
    for (const RunResult& run : runs) values.push_back(field(run));
    std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
    return values[values.size() / 2];
  };
  RunResult result = runs.front();
  result.ms_per_frame = median([](const RunResult& r) { return r.ms_per_frame; });
  result.per_frame.matrix_s = median([](const RunResult& r) { return r.per_frame.matrix_s; });
  result.per_frame.skinning_s = median([](const RunResult& r) { return r.per_frame.skinning_s; });
  result.per_frame.output_s = median([](const RunResult& r) { return r.per_frame.output_s; });
  return result;
}

struct Quality {
  double mean_error_px = 0, max_error_px = 0;
  std::vector<int> characters_per_level;  // at the last sampled frame, levels 0..7+
};

// Every kQualityEvery-th frame: each character at its level of `ladder` (with hysteresis,
// as the run chose it) against full detail, the error in pixels of every original vertex.
Quality MeasureQuality(const std::vector<CharacterType>& types, std::vector<Instance> crowd,
                       int ladder, const Options& o) {
  Quality quality;
  size_t max_vertices = 0, max_kept = 0;
  for (const CharacterType& type : types) {
    max_vertices = std::max(max_vertices, type.mesh.positions.size() / 3);
    max_kept = std::max<size_t>(max_kept, type.ladders.front().level_set.joint_count());
  }
  std::vector<float> level_positions(3 * max_vertices), full_positions(3 * max_vertices);
  std::vector<float> palette(max_kept * proto::kMatrixFloats);
  double sum = 0;
  uint64_t count = 0;
  for (int frame = 0; frame < o.frames; ++frame) {
    const bool sample = frame % kQualityEvery == 0;
    if (sample) quality.characters_per_level.assign(8, 0);
    for (Instance& instance : crowd) {
      const CharacterType& type = types[static_cast<size_t>(instance.type)];
      const Ladder& drawn = type.ladders[static_cast<size_t>(ladder)];
      const double px = PixelHeightAt(instance.distance_m);
      instance.level = drawn.selector->Choose(px, instance.level);
      if (!sample) continue;
      ++quality.characters_per_level[static_cast<size_t>(std::min(instance.level, 7))];
      const auto [clip, t] = ClipFrame(drawn.level_set, frame, instance.phase);
      auto skin_at = [&](int level, std::vector<float>& out) {
        const proto::LevelView& view = drawn.level_set.level(static_cast<uint32_t>(level));
        const std::span<float> matrices(palette.data(), view.kept_count() * proto::kMatrixFloats);
        if (!client::PlayFrame(drawn.level_set, view, clip, t, matrices).ok()) std::abort();
        const LevelSkin& skin = drawn.skins[static_cast<size_t>(level)];
        const SkinFrameJob job{&skin,
                               matrices,
                               drawn.level_set.rigid(),
                               {out.data(), 3 * size_t{skin.vertex_count()}},
                               {}};
        if (!job.Run().ok()) std::abort();
      };
      skin_at(instance.level, level_positions);
      skin_at(0, full_positions);
      const double px_per_unit = px / type.height;
      const size_t p = type.mesh.positions.size() / 3;
      const std::vector<core::SurfacePoint>& points =
          drawn.correspondence[static_cast<size_t>(instance.level)];
      for (size_t i = 0; i < p; ++i) {
        double drawn_at[3] = {0, 0, 0};
        if (points.empty()) {
          for (int a = 0; a < 3; ++a) drawn_at[a] = level_positions[3 * i + a];
        } else {
          for (int corner = 0; corner < 3; ++corner) {
            const float w = points[i].weights[corner];
            const uint32_t v = points[i].vertices[corner];
            for (int a = 0; a < 3; ++a) drawn_at[a] += w * level_positions[3 * v + a];
          }
        }
        const double dx = drawn_at[0] - full_positions[3 * i];
        const double dy = drawn_at[1] - full_positions[3 * i + 1];
        const double dz = drawn_at[2] - full_positions[3 * i + 2];
        const double error = std::sqrt(dx * dx + dy * dy + dz * dz) * px_per_unit;
        sum += error;
        quality.max_error_px = std::max(quality.max_error_px, error);
      }
      count += p;
    }
  }
  quality.mean_error_px = count > 0 ? sum / static_cast<double>(count) : 0;
  while (!quality.characters_per_level.empty() && quality.characters_per_level.back() == 0)
    quality.characters_per_level.pop_back();
  return quality;
}

// The cost model's constants (pipeline/cost_levels.h) as this machine's skinner measures
// them, on the crowd's mesh with the most influences: its vertices kept to their k heaviest
// influences (k = 1 to 4, weights renormalised), drawn whole and as its first vertex alone
// (skinning and output, medians of many runs); then one level of every character's ladder playing 8
// frames of matrices, stored or interpolated. Printed per vertex, per joint and per draw in
// ns, and in units of one influence's blend.
void FitCostModel(const std::vector<CharacterType>& types, nlohmann::json& report) {
  constexpr int kRepetitions = 51;
  constexpr size_t kFewVertices = 1;
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  const CharacterType& largest = *std::max_element(
      types.begin(), types.end(), [](const CharacterType& a, const CharacterType& b) {
        return a.mesh.influence_joints.size() < b.mesh.influence_joints.size();
      });
  const SkinMesh& mesh = largest.mesh;
  const size_t p = mesh.positions.size() / 3;
  const uint32_t n = largest.ladders.front().level_set.joint_count();
  std::vector<uint16_t> identity(n);
  for (uint32_t j = 0; j < n; ++j) identity[j] = static_cast<uint16_t>(j);
  std::vector<float> palette(n * proto::kMatrixFloats, 0.0f);
  for (uint32_t j = 0; j < n; ++j) palette[j * 12] = palette[j * 12 + 5] = palette[j * 12 + 10] = 1;
  std::vector<float> positions(3 * p), normals(3 * p), output(6 * p);
  // Per k: ns per vertex (the slope between the two sizes), the mean influences.
  std::vector<std::array<double, 3>> per_k;  // k, influences, ns per vertex
  double draw_ns = 0;
  for (uint32_t k = 1; k <= 4; ++k) {
    std::vector<uint32_t> offsets{0};
    std::vector<int32_t> joints;
    std::vector<float> weights;
    for (size_t i = 0; i < p; ++i) {
      std::vector<std::pair<float, int32_t>> entries;
      for (uint32_t e = mesh.influence_offsets[i]; e < mesh.influence_offsets[i + 1]; ++e)
        entries.emplace_back(mesh.influence_weights[e], mesh.influence_joints[e]);
      std::sort(entries.rbegin(), entries.rend());
      entries.resize(std::min<size_t>(entries.size(), k));
      float sum = 0;
      for (const auto& entry : entries) sum += entry.first;
      for (const auto& [w, j] : entries) {
        joints.push_back(j);
        weights.push_back(entries.size() == 1 ? 1.0f : w / sum);
      }
      offsets.push_back(static_cast<uint32_t>(joints.size()));
    }
    double ns[2] = {0, 0}, influences = 0;
    for (int size = 0; size < 2; ++size) {
      const size_t v = size == 0 ? p : std::min(p, kFewVertices);
      const SkinMesh part{mesh.positions.first(3 * v), mesh.normals.first(3 * v),
                          std::span(offsets).first(v + 1), std::span(joints).first(offsets[v]),
                          std::span(weights).first(offsets[v])};
      auto skin = LevelSkin::Build(part, identity, n);
      if (!skin.ok()) std::abort();  // built from a mesh that drew: a bug
      if (size == 0) influences = skin->mean_influences();
      std::vector<double> times;
      for (int r = 0; r < kRepetitions; ++r) {
        const Clock::time_point t0 = Clock::now();
        const SkinFrameJob job{&*skin, palette, true, std::span(positions).first(3 * v),
                               std::span(normals).first(3 * v)};
        if (!job.Run().ok()) std::abort();
        std::memcpy(output.data(), positions.data(), 3 * v * sizeof(float));
        std::memcpy(output.data() + 3 * v, normals.data(), 3 * v * sizeof(float));
        times.push_back(std::chrono::duration<double, std::nano>(Clock::now() - t0).count());
      }
      ns[size] = median(times);
    }
    const double few = static_cast<double>(std::min(p, kFewVertices));
    const double slope = (ns[0] - ns[1]) / (static_cast<double>(p) - few);
    per_k.push_back({double(k), influences, slope});
    draw_ns += (ns[1] - few * slope) / 4;
  }
  // A vertex's cost a + b I from the blending path (k = 2 to 4).
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (size_t k = 1; k < per_k.size(); ++k) {
    sx += per_k[k][1];
    sy += per_k[k][2];
    sxx += per_k[k][1] * per_k[k][1];
    sxy += per_k[k][1] * per_k[k][2];
  }
  const double b = (3 * sxy - sx * sy) / (3 * sxx - sx * sx), a = (sy - b * sx) / 3;
  // A joint: the matrix update of every level of every ladder, per joint.
  double stored_ns = 0, interpolated_ns = 0, stored_joints = 0, interpolated_joints = 0;
  for (const CharacterType& type : types) {
    const Ladder& ladder = type.ladders.front();
    for (const proto::LevelView& view : ladder.level_set.levels()) {
      std::vector<float> matrices(view.kept_count() * proto::kMatrixFloats);
      const uint32_t frames = std::min<uint32_t>(8, ladder.level_set.clip(0).frame_count);
      std::vector<double> times;
      for (int r = 0; r < kRepetitions; ++r) {
        const Clock::time_point t0 = Clock::now();
        for (uint32_t t = 0; t < frames; ++t) {
          if (!client::PlayFrame(ladder.level_set, view, 0, t, matrices).ok()) std::abort();
        }
        times.push_back(std::chrono::duration<double, std::nano>(Clock::now() - t0).count() / frames);
      }
      (view.frame_stride() > 1 ? interpolated_ns : stored_ns) += median(times);
      (view.frame_stride() > 1 ? interpolated_joints : stored_joints) += view.kept_count();
    }
  }
  const double joint_ns = stored_ns / std::max(stored_joints, 1.0),
               interpolated_joint_ns = interpolated_ns / std::max(interpolated_joints, 1.0);
  std::printf("\nCost model on this machine (%s, %zu vertices): ns per vertex by influences",
              largest.label.c_str(), p);
  for (const auto& [k, influences, slope] : per_k)
    std::printf("%s k=%.0f (%.2f) %.2f", k > 1 ? "," : "", k, influences, slope);
  std::printf(
      "; fit %.2f + %.2f per influence; a draw %.0f ns; a joint %.2f ns stored, %.2f ns "
      "interpolated (with its draw's share). In influences: vertex %.2f, joint %.2f, "
      "interpolated joint %.1f, draw %.0f\n",
      a, b, draw_ns, joint_ns, interpolated_joint_ns, a / b, joint_ns / b,
      interpolated_joint_ns / b, draw_ns / b);
  report["cost_model"] = {{"vertex_ns", a},      {"influence_ns", b},
                          {"draw_ns", draw_ns},  {"joint_ns", joint_ns},
                          {"interpolated_joint_ns", interpolated_joint_ns},
                          {"single_influence_vertex_ns", per_k.front()[2]}};
}

int Main(int argc, char** argv) {
  Options o;
  if (!ParseOptions(argc, argv, o)) return 2;
  std::vector<CharacterType> types;
  const fs::path dir = o.data / "characters";
  std::vector<fs::path> files;
  if (fs::is_directory(dir)) {
    for (const auto& entry : fs::directory_iterator(dir)) {
      const std::string ext = entry.path().extension().string();
      if (ext == ".glb" || ext == ".gltf" || ext == ".dae") files.push_back(entry.path());
    }
  }
  std::sort(files.begin(), files.end());
  for (const fs::path& file : files) {
    std::fprintf(stderr, "crowd: baking %s\n", file.filename().c_str());
    if (auto type = LoadType(file, o)) types.push_back(std::move(*type));
  }
  if (types.empty()) {
    std::fprintf(stderr, "crowd: no animated skinned character under %s\n", dir.c_str());
    return 2;
  }

  // The scene: uniform density over the wedge's area, so the count grows with distance.
  std::mt19937_64 random(20061);
  std::uniform_real_distribution<double> unit(0, 1);
  std::vector<Instance> crowd(static_cast<size_t>(o.characters));
  size_t vertices = 0;
  for (size_t c = 0; c < crowd.size(); ++c) {
    Instance& instance = crowd[c];
    instance.type = static_cast<int>(c % types.size());
    instance.distance_m =
        std::sqrt(kNearM * kNearM + unit(random) * (kFarM * kFarM - kNearM * kNearM));
    instance.phase = static_cast<int>(random() % 100000);
    instance.vertex_offset = vertices;
    vertices += types[static_cast<size_t>(instance.type)].mesh.positions.size() / 3;
  }
  std::vector<float> vertex_buffer(vertices * 6);

  std::printf("## Crowd: %d characters, %d frames, %zu vertices per frame at full detail\n\n",
              o.characters, o.frames, vertices);
  std::printf(
      "Levels by cost (every part cut): joints / vertices / mean influences / frame stride / "
      "max error %% / cost per level\n\n| character | levels |\n|---|---|\n");
  nlohmann::json report;
  for (const CharacterType& type : types) {
    std::string levels;
    const Ladder& ladder = type.ladders.front();
    for (uint32_t l = 0; l < ladder.level_set.level_count(); ++l) {
      const proto::LevelView& level = ladder.level_set.level(l);
      char text[128];
      std::snprintf(text, sizeof text, "%s%u / %u / %.2f / %u / %.2f / %.3f", l ? "; " : "",
                    level.kept_count(), ladder.skins[l].vertex_count(),
                    ladder.skins[l].mean_influences(), level.frame_stride(),
                    level.figures().max_vertex_error_pct, level.cost());
      levels += text;
    }
    std::printf("| %s | %s |\n", type.label.c_str(), levels.c_str());
    report["characters"].push_back({{"name", type.label},
                                    {"joints", ladder.level_set.joint_count()},
                                    {"vertices", type.mesh.positions.size() / 3},
                                    {"levels", levels}});
  }

  FitCostModel(types, report);

  std::printf(
      "\nScreen-space error against full detail (every %dth frame, every vertex of every "
      "character):\n\n| ladder | mean px | max px | characters per level (last sample) |\n"
      "|---|---|---|---|\n",
      kQualityEvery);
  for (size_t k = 0; k < types.front().ladders.size(); ++k) {
    const Quality quality = MeasureQuality(types, crowd, static_cast<int>(k), o);
    std::string per_level;
    for (size_t l = 0; l < quality.characters_per_level.size(); ++l)
      per_level += (l ? " " : "") + std::string("L") + std::to_string(l) + " " +
                   std::to_string(quality.characters_per_level[l]);
    std::printf("| %s | %.4f | %.3f | %s |\n", kLadderKinds[k].name, quality.mean_error_px,
                quality.max_error_px, per_level.c_str());
    report["quality"].push_back({{"ladder", kLadderKinds[k].name},
                                 {"mean_error_px", quality.mean_error_px},
                                 {"max_error_px", quality.max_error_px},
                                 {"characters_per_level", quality.characters_per_level}});
  }

  std::printf(
      "\n| threads | crowd | CPU ms/frame | speedup (CPU) | wall ms/frame | speedup (wall) | "
      "matrix MB/frame | matrix update ms | skinning ms | output ms |\n"
      "|---|---|---|---|---|---|---|---|---|---|\n");
  const int ladders = static_cast<int>(types.front().ladders.size());
  for (int threads : o.threads) {
    std::vector<std::vector<RunResult>> runs(static_cast<size_t>(ladders) +
                                             1);  // full detail, then each ladder
    for (int r = 0; r < o.repetitions; ++r) {
      for (int m = -1; m < ladders; ++m)
        runs[static_cast<size_t>(m + 1)].push_back(
            RunCrowd(types, crowd, vertex_buffer, m, threads, o));
    }
    std::vector<RunResult> results;
    for (auto& run : runs) results.push_back(Median(run));
    const RunResult& full = results.front();
    const double saving = full.per_frame.total_s() - results[1].per_frame.total_s();
    for (const RunResult& run : results) {
      const char* name = run.ladder < 0 ? "full detail" : kLadderKinds[run.ladder].name;
      std::printf("| %d | %s | %.2f | %.2fx | %.2f | %.2fx | %.3f | %.2f | %.2f | %.2f |\n",
                  threads, name, run.per_frame.total_s() * 1e3,
                  full.per_frame.total_s() / run.per_frame.total_s(), run.ms_per_frame,
                  full.ms_per_frame / run.ms_per_frame, run.per_frame.matrix_bytes / 1e6,
                  run.per_frame.matrix_s * 1e3, run.per_frame.skinning_s * 1e3,
                  run.per_frame.output_s * 1e3);
      nlohmann::json entry = {{"threads", threads},
                              {"crowd", name},
                              {"wall_ms_per_frame", run.ms_per_frame},
                              {"cpu_ms_per_frame", run.per_frame.total_s() * 1e3},
                              {"matrix_bytes_per_frame", run.per_frame.matrix_bytes},
                              {"matrix_update_ms", run.per_frame.matrix_s * 1e3},
                              {"skinning_ms", run.per_frame.skinning_s * 1e3},
                              {"output_ms", run.per_frame.output_s * 1e3}};
      // A part's share of the saving: what switching it off gives back.
      if (run.ladder > 0 && saving > 0) {
        entry["share_of_saving"] =
            (run.per_frame.total_s() - results[1].per_frame.total_s()) / saving;
      }
      report["runs"].push_back(entry);
    }
    if (saving > 0 && ladders > 1) {
      std::printf("\nShare of the saving (%d threads), what switching a part off gives back:",
                  threads);
      for (int k = 1; k < ladders; ++k) {
        std::printf(" %s %.0f%%;", kLadderKinds[k].name,
                    100 *
                        (results[static_cast<size_t>(k + 1)].per_frame.total_s() -
                         results[1].per_frame.total_s()) /
                        saving);
      }
      std::printf("\n\n");
    }
  }
  std::printf("\n(CPU times are summed over the threads, per frame; medians of %d runs)\n",
              o.repetitions);
  if (!o.json_path.empty()) std::ofstream(o.json_path) << report.dump(2) << "\n";
  return 0;
}

}  // namespace
}  // namespace motionlod::bench

int main(int argc, char** argv) { return motionlod::bench::Main(argc, argv); }
