#include "io/asset_wire.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <set>
#include <type_traits>
#include <unordered_set>
#include <utility>

#include "base/hash.h"
#include "core/character.h"
#include "io/asset_impl.h"

namespace motionlod::io {
namespace {

// Values are copied as their in-memory bytes; the format is little-endian.
static_assert(std::endian::native == std::endian::little, "the wire format is little-endian");

constexpr char kMagic[8] = {'M', 'L', 'O', 'D', 'W', 'I', 'R', 'E'};
constexpr size_t kMaxNameBytes = size_t{64} << 10;   // file, joint and clip names
constexpr size_t kMaxMessageText = size_t{1} << 20;  // a warning or an error message
constexpr double kMaxClipSeconds = 24 * 3600;        // BuildClips' bound: a day
constexpr double kUnitTolerance = 1e-3;              // |q| of a rotation key

class Writer {
 public:
  template <typename T>
  void Value(const T& value) {
    static_assert(std::is_arithmetic_v<T>);
    out_.append(reinterpret_cast<const char*>(&value), sizeof(T));
  }
  void Count(size_t count) { Value(static_cast<uint32_t>(count)); }
  void String(std::string_view text) {
    Count(text.size());
    out_.append(text);
  }
  void Bytes(std::string_view bytes) {
    Value(static_cast<uint64_t>(bytes.size()));
    out_.append(bytes);
  }
  // A fixed-size Eigen matrix or vector, its coefficients in storage order.
  template <typename M>
  void Fixed(const M& m) {
    out_.append(reinterpret_cast<const char*>(m.data()), sizeof(typename M::Scalar) * m.size());
  }
  template <typename T>
  void Values(const std::vector<T>& values) {
    Count(values.size());
    for (const T& v : values) Value(v);
  }
  template <typename M>
  void FixedList(const std::vector<M>& list) {
    Count(list.size());
    for (const M& m : list) Fixed(m);
  }
  void Strings(const std::vector<std::string>& list) {
    Count(list.size());
    for (const std::string& s : list) String(s);
  }

  // Header + payload.
  std::string Finish(MessageKind kind) const {
    std::string message(kWireHeaderBytes, '\0');
    std::memcpy(message.data(), kMagic, 8);
    const uint16_t version = kAssetWireVersion, kind_value = static_cast<uint16_t>(kind);
    const uint64_t size = out_.size(), checksum = Fnv1a64(out_);
    std::memcpy(message.data() + 8, &version, 2);
    std::memcpy(message.data() + 10, &kind_value, 2);
    std::memcpy(message.data() + 16, &size, 8);
    std::memcpy(message.data() + 24, &checksum, 8);
    return message + out_;
  }

 private:
  std::string out_;
};

// Reads the payload; the first failure sticks (later reads return zeros) so that the
// decoders read straight through and check ok() once.
class Reader {
 public:
  explicit Reader(std::string_view bytes) : bytes_(bytes) {}
  bool ok() const { return error_.empty(); }
  const std::string& error() const { return error_; }
  bool at_end() const { return position_ == bytes_.size(); }
  void Fail(const std::string& why) {
    if (error_.empty()) error_ = why;
  }

  template <typename T>
  T Value() {
    static_assert(std::is_arithmetic_v<T>);
    T value{};
    if (Take(sizeof(T), "a value"))
      std::memcpy(&value, bytes_.data() + position_ - sizeof(T), sizeof(T));
    return value;
  }
  // A count of elements that take at least `element_bytes` each: never more than the
  // bytes left can hold, so nothing is allocated for data that is not there.
  size_t Count(size_t element_bytes, const char* what) {
    const uint32_t count = Value<uint32_t>();
    if (element_bytes > 0 && count > (bytes_.size() - position_) / element_bytes) {
      Fail(std::string(what) + ": " + std::to_string(count) + " entries do not fit in the " +
           std::to_string(bytes_.size() - position_) + " bytes left");
      return 0;
    }
    return ok() ? count : 0;
  }
  std::string String(size_t max_bytes, const char* what) {
    const size_t size = Count(1, what);
    if (size > max_bytes)
      Fail(std::string(what) + " is longer than " + std::to_string(max_bytes) + " bytes");
    if (!ok()) return {};
    position_ += size;
    return std::string(bytes_.substr(position_ - size, size));
  }
  std::string Bytes(const char* what) {
    const uint64_t size = Value<uint64_t>();
    if (!ok()) return {};
    if (size > bytes_.size() - position_) {
      Fail(std::string(what) + " is cut off");
      return {};
    }
    position_ += size;
    return std::string(bytes_.substr(position_ - size, size));
  }
  template <typename M>
  void Fixed(M& m) {
    constexpr size_t bytes = sizeof(typename M::Scalar) * M::SizeAtCompileTime;
    if (Take(bytes, "a matrix")) std::memcpy(m.data(), bytes_.data() + position_ - bytes, bytes);
  }
  template <typename T>
  std::vector<T> Values(const char* what) {
    std::vector<T> values(Count(sizeof(T), what));
    for (T& v : values) v = Value<T>();
    return values;
  }
  template <typename M>
  std::vector<M> FixedList(const char* what) {
    std::vector<M> list(Count(sizeof(typename M::Scalar) * M::SizeAtCompileTime, what));
    for (M& m : list) Fixed(m);
    return list;
  }
  std::vector<std::string> Strings(size_t max_bytes, const char* what) {
    std::vector<std::string> list(Count(4, what));
    for (std::string& s : list) s = String(max_bytes, what);
    return list;
  }

 private:
  bool Take(size_t size, const char* what) {
    if (!ok()) return false;
    if (size > bytes_.size() - position_) {
      Fail(std::string("the payload is cut off in ") + what);
      return false;
    }
    position_ += size;
    return true;
  }

  std::string_view bytes_;
  size_t position_ = 0;
  std::string error_;
};

// Checks the header and returns the payload.
StatusOr<std::string_view> OpenMessage(std::string_view message, MessageKind kind) {
  StatusOr<uint64_t> total = WireMessageBytes(message);
  if (!total.ok()) return total.status();
  uint16_t kind_value = 0;
  uint32_t reserved = 0;
  uint64_t checksum = 0;
  std::memcpy(&kind_value, message.data() + 10, 2);
  std::memcpy(&reserved, message.data() + 12, 4);
  std::memcpy(&checksum, message.data() + 24, 8);
  if (kind_value != static_cast<uint16_t>(kind)) {
    return DataLoss("message kind " + std::to_string(kind_value) + " where " +
                    std::to_string(static_cast<int>(kind)) + " was expected");
  }
  if (reserved != 0) return DataLoss("the reserved header field is not zero");
  if (*total != message.size()) {
    return DataLoss("the header declares " + std::to_string(*total) +
                    " bytes but the message has " + std::to_string(message.size()));
  }
  const std::string_view payload = message.substr(kWireHeaderBytes);
  if (Fnv1a64(payload) != checksum) return DataLoss("the payload checksum does not match");
  return payload;
}

bool Finite(double value) { return std::isfinite(value); }
bool Finite(const Eigen::Quaterniond& q) { return q.coeffs().allFinite(); }
template <typename M>
bool Finite(const M& m) {
  return m.allFinite();
}
template <typename T>
bool AllFinite(const std::vector<T>& values) {
  return std::all_of(values.begin(), values.end(), [](const T& v) { return Finite(v); });
}

// ---------------------------------------------------------------------------------------
// Asset payload: character (name; joints: names, parents, bind matrices; skin: positions,
// normals, triangles, influence offsets, joints and weights), proxy flag, joint nodes,
// nodes (parent, local, translation, rotation, scale), clips (name, duration, source fps,
// frame count; tracks: node, then position, rotation and scaling keys as times and
// values), warnings.

void WriteKeys(Writer& w, const NodeKeys& keys) {
  w.Values(keys.position_times);
  w.FixedList(keys.positions);
  w.Values(keys.rotation_times);
  w.Count(keys.rotations.size());
  for (const Eigen::Quaterniond& q : keys.rotations) w.Fixed(q.coeffs());
  w.Values(keys.scaling_times);
  w.FixedList(keys.scalings);
}

void ReadKeys(Reader& r, NodeKeys& keys) {
  keys.position_times = r.Values<double>("position times");
  keys.positions = r.FixedList<Eigen::Vector3d>("positions");
  keys.rotation_times = r.Values<double>("rotation times");
  keys.rotations.resize(r.Count(4 * sizeof(double), "rotations"));
  for (Eigen::Quaterniond& q : keys.rotations) r.Fixed(q.coeffs());
  keys.scaling_times = r.Values<double>("scaling times");
  keys.scalings = r.FixedList<Eigen::Vector3d>("scalings");
}

void WriteAsset(Writer& w, const Asset::Impl& impl) {
  const core::RawCharacter& c = impl.rig.character;
  w.String(c.name);
  w.Strings(c.skeleton.joint_names);
  w.Values(c.skeleton.parents);
  w.FixedList(c.skeleton.bind_world);
  w.FixedList(c.skin.positions);
  w.FixedList(c.skin.normals);
  w.Count(c.skin.triangles.size());
  for (const auto& triangle : c.skin.triangles) {
    for (uint32_t index : triangle) w.Value(index);
  }
  w.Values(c.skin.influence_offsets);
  w.Values(c.skin.influence_joints);
  w.Values(c.skin.influence_weights);
  w.Value(static_cast<uint8_t>(impl.rig.proxy_skin ? 1 : 0));
  w.Values(impl.rig.joint_nodes);
  w.Count(impl.nodes.size());
  for (const SceneNode& node : impl.nodes) {
    w.Value(static_cast<int32_t>(node.parent));
    w.Fixed(node.local);
    w.Fixed(node.translation);
    w.Fixed(node.rotation.coeffs());
    w.Fixed(node.scale);
  }
  w.Count(impl.clips.size());
  for (const Clip& clip : impl.clips) {
    w.String(clip.info.name);
    w.Value(clip.info.duration_seconds);
    w.Value(clip.info.source_fps);
    w.Value(static_cast<int32_t>(clip.info.source_frame_count));
    w.Count(clip.tracks.size());
    for (const Track& track : clip.tracks) {
      w.Value(static_cast<int32_t>(track.node));
      WriteKeys(w, track);
    }
  }
  w.Strings(impl.warnings);
}

void ReadAsset(Reader& r, Asset::Impl& impl) {
  core::RawCharacter& c = impl.rig.character;
  c.name = r.String(kMaxNameBytes, "the character name");
  c.skeleton.joint_names = r.Strings(kMaxNameBytes, "joint names");
  c.skeleton.parents = r.Values<int>("joint parents");
  c.skeleton.bind_world = r.FixedList<core::Affine34d>("bind matrices");
  c.skin.positions = r.FixedList<core::Vec3f>("vertex positions");
  c.skin.normals = r.FixedList<core::Vec3f>("vertex normals");
  c.skin.triangles.resize(r.Count(3 * sizeof(uint32_t), "triangles"));
  for (auto& triangle : c.skin.triangles) {
    for (uint32_t& index : triangle) index = r.Value<uint32_t>();
  }
  c.skin.influence_offsets = r.Values<uint32_t>("influence offsets");
  c.skin.influence_joints = r.Values<int32_t>("influence joints");
  c.skin.influence_weights = r.Values<float>("influence weights");
  const uint8_t proxy = r.Value<uint8_t>();
  if (proxy > 1) r.Fail("the proxy skin flag is neither 0 nor 1");
  impl.rig.proxy_skin = proxy == 1;
  impl.rig.joint_nodes = r.Values<int>("joint nodes");
  constexpr size_t kNodeBytes = 4 + 8 * (12 + 3 + 4 + 3);
  impl.nodes.resize(r.Count(kNodeBytes, "nodes"));
  for (SceneNode& node : impl.nodes) {
    node.parent = r.Value<int32_t>();
    r.Fixed(node.local);
    r.Fixed(node.translation);
    r.Fixed(node.rotation.coeffs());
    r.Fixed(node.scale);
  }
  constexpr size_t kClipBytes = 4 + 8 + 8 + 4 + 4;
  impl.clips.resize(r.Count(kClipBytes, "clips"));
  for (Clip& clip : impl.clips) {
    clip.info.name = r.String(kMaxNameBytes, "a clip name");
    clip.info.duration_seconds = r.Value<double>();
    clip.info.source_fps = r.Value<double>();
    clip.info.source_frame_count = r.Value<int32_t>();
    clip.tracks.resize(r.Count(4 + 6 * 4, "tracks"));
    for (Track& track : clip.tracks) {
      track.node = r.Value<int32_t>();
      ReadKeys(r, track);
    }
  }
  impl.warnings = r.Strings(kMaxMessageText, "warnings");
}

template <typename T>
Status ValidateKeyList(const std::vector<double>& times, const std::vector<T>& values,
                       const std::string& where) {
  if (times.size() != values.size()) {
    return DataLoss(where + " has " + std::to_string(times.size()) + " key times but " +
                    std::to_string(values.size()) + " values");
  }
  if (!AllFinite(times) || !AllFinite(values)) return DataLoss(where + " has non-finite keys");
  if (!std::is_sorted(times.begin(), times.end()))
    return DataLoss(where + " has unsorted key times");
  return Status::Ok();
}

// Everything SampleAnimation, RetargetAnimation and BuildCharacter rely on.
Status ValidateAsset(const Asset::Impl& impl) {
  if (Status s = core::ValidateRawCharacter(impl.rig.character); !s.ok()) {
    return DataLoss("the character does not validate: " + s.message());
  }
  const size_t node_count = impl.nodes.size();
  if (node_count == 0) return DataLoss("the asset has no nodes");
  for (size_t k = 0; k < node_count; ++k) {
    const SceneNode& node = impl.nodes[k];
    if (node.parent < -1 || node.parent >= static_cast<int>(k) || (k == 0) != (node.parent == -1)) {
      return DataLoss("node " + std::to_string(k) + " has parent " + std::to_string(node.parent) +
                      "; nodes must follow their parent and only node 0 is a root");
    }
    if (!Finite(node.local) || !Finite(node.translation) || !Finite(node.rotation) ||
        !Finite(node.scale)) {
      return DataLoss("node " + std::to_string(k) + " has a non-finite rest transform");
    }
  }
  const std::vector<int>& joint_nodes = impl.rig.joint_nodes;
  if (joint_nodes.size() != impl.rig.character.skeleton.parents.size()) {
    return DataLoss(std::to_string(joint_nodes.size()) + " joint nodes for " +
                    std::to_string(impl.rig.character.skeleton.parents.size()) + " joints");
  }
  std::unordered_set<int> distinct_joint_nodes;
  for (int node : joint_nodes) {
    if (node < 0 || static_cast<size_t>(node) >= node_count ||
        !distinct_joint_nodes.insert(node).second) {
      return DataLoss("joint node " + std::to_string(node) + " is out of range or repeated");
    }
  }
  std::set<std::string> clip_names;
  for (const Clip& clip : impl.clips) {
    const AnimationInfo& info = clip.info;
    const std::string where = "clip '" + info.name.substr(0, 64) + "'";
    if (info.name.empty() || !clip_names.insert(info.name).second) {
      return DataLoss("a clip name is empty or repeated");
    }
    if (!(info.duration_seconds >= 0 && info.duration_seconds <= kMaxClipSeconds) ||
        !(info.source_fps > 0 && std::isfinite(info.source_fps)) ||
        info.source_frame_count != FrameCount(info.duration_seconds, info.source_fps)) {
      return DataLoss(where + " has an inconsistent duration, rate or frame count");
    }
    std::unordered_set<int> track_nodes;
    for (const Track& track : clip.tracks) {
      if (track.node < 0 || static_cast<size_t>(track.node) >= node_count ||
          !track_nodes.insert(track.node).second) {
        return DataLoss(where + " animates node " + std::to_string(track.node) +
                        ", out of range or twice");
      }
      if (Status s = ValidateKeyList(track.position_times, track.positions, where); !s.ok())
        return s;
      if (Status s = ValidateKeyList(track.rotation_times, track.rotations, where); !s.ok())
        return s;
      if (Status s = ValidateKeyList(track.scaling_times, track.scalings, where); !s.ok()) return s;
      for (const Eigen::Quaterniond& q : track.rotations) {
        if (std::abs(q.norm() - 1.0) > kUnitTolerance)
          return DataLoss(where + " has a rotation key that is not unit");
      }
    }
  }
  return Status::Ok();
}

}  // namespace

StatusOr<uint64_t> WireMessageBytes(std::string_view bytes) {
  if (bytes.size() < kWireHeaderBytes) {
    return DataLoss("the message is cut off in its header (" + std::to_string(bytes.size()) +
                    " bytes)");
  }
  if (std::memcmp(bytes.data(), kMagic, 8) != 0)
    return DataLoss("the message does not start with MLODWIRE");
  uint16_t version = 0, kind = 0;
  uint64_t payload = 0;
  std::memcpy(&version, bytes.data() + 8, 2);
  std::memcpy(&kind, bytes.data() + 10, 2);
  std::memcpy(&payload, bytes.data() + 16, 8);
  if (version != kAssetWireVersion)
    return DataLoss("wire version " + std::to_string(version) + " is not " +
                    std::to_string(kAssetWireVersion));
  if (kind < 1 || kind > 3) return DataLoss("unknown message kind " + std::to_string(kind));
  if (payload > UINT64_MAX - kWireHeaderBytes) return DataLoss("the declared size overflows");
  return payload + kWireHeaderBytes;
}

// Request payload: max_influences (i32), max_total_bytes (u64), max_joints (i32),
// max_vertices, max_frames, max_joint_frames (i64 each), allowed extensions (strings),
// files (count, then each: name string, bytes as u64 size and bytes).
std::string EncodeImportRequest(const std::vector<SourceFile>& files, const LoadOptions& options) {
  Writer w;
  w.Value(static_cast<int32_t>(options.max_influences));
  w.Value(static_cast<uint64_t>(options.max_total_bytes));
  w.Value(static_cast<int32_t>(options.max_joints));
  w.Value(static_cast<int64_t>(options.max_vertices));
  w.Value(static_cast<int64_t>(options.max_frames));
  w.Value(static_cast<int64_t>(options.max_joint_frames));
  w.Strings(options.allowed_extensions);
  w.Count(files.size());
  for (const SourceFile& f : files) {
    w.String(f.name);
    w.Bytes(f.bytes);
  }
  return w.Finish(MessageKind::kImportRequest);
}

StatusOr<ImportRequest> DecodeImportRequest(std::string_view message) {
  StatusOr<std::string_view> payload = OpenMessage(message, MessageKind::kImportRequest);
  if (!payload.ok()) return payload.status();
  Reader r(*payload);
  ImportRequest request;
  request.options.max_influences = r.Value<int32_t>();
  request.options.max_total_bytes = static_cast<size_t>(r.Value<uint64_t>());
  request.options.max_joints = r.Value<int32_t>();
  request.options.max_vertices = r.Value<int64_t>();
  request.options.max_frames = r.Value<int64_t>();
  request.options.max_joint_frames = r.Value<int64_t>();
  request.options.allowed_extensions = r.Strings(kMaxNameBytes, "extensions");
  request.files.resize(r.Count(4 + 8, "files"));
  for (SourceFile& f : request.files) {
    f.name = r.String(kMaxNameBytes, "a file name");
    f.bytes = r.Bytes("a file");
  }
  if (r.ok() && !r.at_end()) r.Fail("bytes follow the last file");
  if (!r.ok()) return DataLoss("malformed import request: " + r.error());
  if (Status s = request.options.Validate(); !s.ok()) return s;
  return request;
}

// Error payload: status code (u32), message (string).
std::string EncodeImportReply(const StatusOr<std::shared_ptr<const Asset>>& result) {
  Writer w;
  if (!result.ok()) {
    w.Value(static_cast<uint32_t>(result.status().code()));
    w.String(std::string_view(result.status().message()).substr(0, kMaxMessageText));
    return w.Finish(MessageKind::kErrorReply);
  }
  WriteAsset(w, AssetFactory::ImplOf(**result));
  return w.Finish(MessageKind::kAssetReply);
}

StatusOr<std::shared_ptr<const Asset>> DecodeImportReply(std::string_view message) {
  const auto malformed = [](const std::string& why) {
    return DataLoss("malformed import reply: " + why);
  };
  StatusOr<uint64_t> total = WireMessageBytes(message);
  if (!total.ok()) return malformed(total.status().message());
  uint16_t kind = 0;
  std::memcpy(&kind, message.data() + 10, 2);
  if (kind == static_cast<uint16_t>(MessageKind::kErrorReply)) {
    StatusOr<std::string_view> payload = OpenMessage(message, MessageKind::kErrorReply);
    if (!payload.ok()) return malformed(payload.status().message());
    Reader r(*payload);
    const uint32_t code = r.Value<uint32_t>();
    std::string text = r.String(kMaxMessageText, "the error message");
    if (r.ok() && !r.at_end()) r.Fail("bytes follow the error message");
    if (!r.ok()) return malformed(r.error());
    const auto status_code = static_cast<StatusCode>(code);
    if (status_code != StatusCode::kInvalidArgument && status_code != StatusCode::kNotFound &&
        status_code != StatusCode::kUnsupported && status_code != StatusCode::kDataLoss) {
      return malformed("status code " + std::to_string(code) + " is not an import error");
    }
    return Status(status_code, std::move(text));
  }
  StatusOr<std::string_view> payload = OpenMessage(message, MessageKind::kAssetReply);
  if (!payload.ok()) return malformed(payload.status().message());
  Reader r(*payload);
  auto impl = std::make_unique<Asset::Impl>();
  ReadAsset(r, *impl);
  if (r.ok() && !r.at_end()) r.Fail("bytes follow the warnings");
  if (!r.ok()) return malformed(r.error());
  if (Status s = ValidateAsset(*impl); !s.ok()) return malformed(s.message());
  for (const Clip& clip : impl->clips) impl->infos.push_back(clip.info);
  return AssetFactory::Make(std::move(impl));
}

}  // namespace motionlod::io
