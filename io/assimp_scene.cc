#include "io/assimp_scene.h"

#include <assimp/BaseImporter.h>
#include <assimp/config.h>
#include <assimp/importerdesc.h>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <assimp/IOStream.hpp>
#include <assimp/IOSystem.hpp>
#include <assimp/Importer.hpp>
#include <cctype>
#include <cmath>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <set>
#include <sstream>
#include <utility>
#include <vector>

#include "io/collada_check.h"
#include "io/text.h"

namespace motionlod::io {
namespace {

// Upper bounds that keep a hostile file from exhausting memory after Assimp accepted it.
constexpr size_t kMaxNodes = 1 << 20;

// ---------------------------------------------------------------------------------------
// In-memory file access.

class MemoryStream final : public Assimp::IOStream {
 public:
  explicit MemoryStream(const std::string& bytes) : bytes_(bytes) {}

  size_t Read(void* buffer, size_t size, size_t count) override {
    if (size == 0 || count == 0 || buffer == nullptr) return 0;
    const size_t whole = std::min(count, (bytes_.size() - position_) / size);
    std::memcpy(buffer, bytes_.data() + position_, whole * size);
    position_ += whole * size;
    return whole;
  }
  size_t Write(const void*, size_t, size_t) override { return 0; }
  aiReturn Seek(size_t offset, aiOrigin origin) override {
    size_t target = 0;
    switch (origin) {
      case aiOrigin_SET:
        target = offset;
        break;
      case aiOrigin_CUR:
        if (offset > bytes_.size() - position_) return AI_FAILURE;
        target = position_ + offset;
        break;
      case aiOrigin_END:
        if (offset > bytes_.size()) return AI_FAILURE;
        target = bytes_.size() - offset;
        break;
      default:
        return AI_FAILURE;
    }
    if (target > bytes_.size()) return AI_FAILURE;
    position_ = target;
    return AI_SUCCESS;
  }
  size_t Tell() const override { return position_; }
  size_t FileSize() const override { return bytes_.size(); }
  void Flush() override {}

 private:
  const std::string& bytes_;
  size_t position_ = 0;
};

bool IsPlainName(const std::string& name) {
  return !name.empty() && name != "." && name != ".." &&
         name.find_first_of("/\\:") == std::string::npos && name.find('\0') == std::string::npos;
}

std::string PercentDecode(const std::string& text) {
  std::string out;
  for (size_t i = 0; i < text.size(); ++i) {
    if (text[i] == '%' && i + 2 < text.size() &&
        std::isxdigit(static_cast<unsigned char>(text[i + 1])) &&
        std::isxdigit(static_cast<unsigned char>(text[i + 2]))) {
      out += static_cast<char>(std::stoi(text.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += text[i];
    }
  }
  return out;
}

// Serves the main file and, by plain name, the files the resolver knows. Everything
// else (directories, "..", absolute paths, URI schemes) is refused and remembered.
class MemoryIoSystem final : public Assimp::IOSystem {
 public:
  MemoryIoSystem(const std::string& main_name, const std::string& main_bytes,
                 const FileResolver& resolver)
      : main_name_(main_name), main_bytes_(main_bytes), resolver_(resolver) {}

  bool Exists(const char* path) const override {
    return Resolve(path, /*remember=*/false) != nullptr;
  }
  char getOsSeparator() const override { return '/'; }
  Assimp::IOStream* Open(const char* path, const char* mode) override {
    if (mode != nullptr && std::strpbrk(mode, "wa+") != nullptr) {
      refused_.insert(std::string(path ? path : "") + " (opened for writing)");
      return nullptr;
    }
    const std::string* bytes = Resolve(path, /*remember=*/true);
    return bytes == nullptr ? nullptr : new MemoryStream(*bytes);
  }
  void Close(Assimp::IOStream* stream) override { delete stream; }
  bool ComparePaths(const char* one, const char* two) const override {
    return one != nullptr && two != nullptr && std::strcmp(one, two) == 0;
  }
  bool PushDirectory(const std::string&) override { return true; }
  bool PopDirectory() override { return true; }
  bool CreateDirectory(const std::string&) override { return false; }
  bool ChangeDirectory(const std::string&) override { return false; }
  bool DeleteFile(const std::string&) override { return false; }

  // References that were asked for and not served, in request order.
  const std::set<std::string>& refused() const { return refused_; }

 private:
  const std::string* Resolve(const char* raw, bool remember) const {
    if (raw == nullptr) return nullptr;
    std::string path(raw);
    while (path.rfind("./", 0) == 0) path.erase(0, 2);
    if (path == main_name_) return &main_bytes_;
    const std::string* found = nullptr;
    if (IsPlainName(path)) {
      found = resolver_(path);
      if (found == nullptr && path.find('%') != std::string::npos) {
        const std::string decoded = PercentDecode(path);
        if (IsPlainName(decoded)) found = decoded == main_name_ ? &main_bytes_ : resolver_(decoded);
      }
    }
    if (found == nullptr && remember) refused_.insert(raw);
    return found;
  }

  std::string main_name_;
  const std::string& main_bytes_;
  const FileResolver& resolver_;
  mutable std::set<std::string> refused_;
};

// ---------------------------------------------------------------------------------------
// aiScene -> Scene.

bool Finite(const aiMatrix4x4& m) {
  const float* v = &m.a1;
  for (int i = 0; i < 16; ++i) {
    if (!std::isfinite(v[i])) return false;
  }
  return true;
}

core::Affine34d ToAffine(const aiMatrix4x4& m) {
  core::Affine34d a;
  for (unsigned r = 0; r < 3; ++r) {
    for (unsigned c = 0; c < 4; ++c) a(r, c) = m[r][c];
  }
  return a;
}

std::string Name(const aiString& s) { return std::string(s.C_Str(), s.length); }

Status NonFinite(const std::string& what) {
  return InvalidArgument("the file holds a non-finite number (NaN or infinity) in " + what);
}

bool MetadataIsNull(const aiNode& node) {
  bool is_null = false;
  return node.mMetaData != nullptr && node.mMetaData->Get("IsNull", is_null) && is_null;
}

Status CopyNodes(const aiScene& ai, Scene& scene) {
  std::vector<std::pair<const aiNode*, int>> stack = {{ai.mRootNode, -1}};
  while (!stack.empty()) {
    const auto [node, parent] = stack.back();
    stack.pop_back();
    if (scene.nodes.size() >= kMaxNodes) {
      return InvalidArgument("the file has more than " + std::to_string(kMaxNodes) + " nodes");
    }
    SceneNode out;
    out.name = Name(node->mName);
    out.parent = parent;
    if (!Finite(node->mTransformation))
      return NonFinite("the transform of node '" + out.name + "'");
    out.local = ToAffine(node->mTransformation);
    out.is_null = MetadataIsNull(*node);
    for (unsigned m = 0; m < node->mNumMeshes; ++m) {
      if (node->mMeshes[m] >= ai.mNumMeshes) {
        return DataLoss("node '" + out.name + "' refers to mesh " +
                        std::to_string(node->mMeshes[m]) + " of " + std::to_string(ai.mNumMeshes));
      }
      out.meshes.push_back(static_cast<int>(node->mMeshes[m]));
    }
    DecomposeLocal(out);
    const int index = static_cast<int>(scene.nodes.size());
    scene.nodes.push_back(std::move(out));
    // Children pushed in reverse so that they pop in file order (preorder).
    for (unsigned c = node->mNumChildren; c-- > 0;) {
      if (node->mChildren[c] != nullptr) stack.emplace_back(node->mChildren[c], index);
    }
  }
  return Status::Ok();
}

bool IsSkeletonMaterial(const aiScene& ai, const aiMesh& mesh) {
  if (mesh.mMaterialIndex >= ai.mNumMaterials) return false;
  aiString name;
  return ai.mMaterials[mesh.mMaterialIndex]->Get(AI_MATKEY_NAME, name) == AI_SUCCESS &&
         std::strcmp(name.C_Str(), "SkeletonMaterial") == 0;
}

Status CopyMesh(const aiScene& ai, const aiMesh& mesh, Format format, SceneMesh& out) {
  out.name = Name(mesh.mName);
  out.synthetic = format == Format::kBvh || IsSkeletonMaterial(ai, mesh);
  const std::string label = "mesh '" + out.name + "'";
  out.positions.resize(mesh.mNumVertices);
  for (unsigned i = 0; i < mesh.mNumVertices; ++i) {
    const aiVector3D& v = mesh.mVertices[i];
    out.positions[i] = Eigen::Vector3f(v.x, v.y, v.z);
    if (!out.positions[i].allFinite())
      return NonFinite("vertex " + std::to_string(i) + " of " + label);
  }
  if (mesh.mNormals != nullptr) {
    out.normals.resize(mesh.mNumVertices);
    for (unsigned i = 0; i < mesh.mNumVertices; ++i) {
      const aiVector3D& n = mesh.mNormals[i];
      out.normals[i] = Eigen::Vector3f(n.x, n.y, n.z);
    }
  }
  out.triangles.reserve(mesh.mNumFaces);
  for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
    const aiFace& face = mesh.mFaces[f];
    if (face.mNumIndices != 3) continue;
    std::array<uint32_t, 3> tri{};
    bool valid = true;
    for (int k = 0; k < 3; ++k) {
      tri[k] = face.mIndices[k];
      valid = valid && tri[k] < mesh.mNumVertices;
    }
    if (!valid)
      return DataLoss("face " + std::to_string(f) + " of " + label + " refers to a missing vertex");
    out.triangles.push_back(tri);
  }
  for (unsigned b = 0; b < mesh.mNumBones; ++b) {
    const aiBone& bone = *mesh.mBones[b];
    SceneBone sb;
    sb.name = Name(bone.mName);
    if (!Finite(bone.mOffsetMatrix))
      return NonFinite("the offset matrix of bone '" + sb.name + "' of " + label);
    sb.offset = ToAffine(bone.mOffsetMatrix);
    sb.weights.reserve(bone.mNumWeights);
    for (unsigned w = 0; w < bone.mNumWeights; ++w) {
      const aiVertexWeight& vw = bone.mWeights[w];
      if (!std::isfinite(vw.mWeight))
        return NonFinite("a weight of bone '" + sb.name + "' of " + label);
      if (vw.mVertexId >= mesh.mNumVertices) {
        return DataLoss("bone '" + sb.name + "' of " + label + " weights the missing vertex " +
                        std::to_string(vw.mVertexId));
      }
      sb.weights.emplace_back(vw.mVertexId, vw.mWeight);
    }
    out.bones.push_back(std::move(sb));
  }
  return Status::Ok();
}

Status CopyAnimation(const aiAnimation& anim, SceneAnimation& out) {
  out.name = Name(anim.mName);
  out.duration_ticks = anim.mDuration;
  out.ticks_per_second = anim.mTicksPerSecond;
  const std::string label = "animation '" + out.name + "'";
  if (!std::isfinite(out.duration_ticks) || !std::isfinite(out.ticks_per_second)) {
    return NonFinite("the duration or rate of " + label);
  }
  for (unsigned c = 0; c < anim.mNumChannels; ++c) {
    const aiNodeAnim& ch = *anim.mChannels[c];
    SceneChannel sc;
    sc.node_name = Name(ch.mNodeName);
    const std::string where = "channel '" + sc.node_name + "' of " + label;
    for (unsigned k = 0; k < ch.mNumPositionKeys; ++k) {
      const aiVectorKey& key = ch.mPositionKeys[k];
      sc.position_times.push_back(key.mTime);
      sc.positions.emplace_back(key.mValue.x, key.mValue.y, key.mValue.z);
      if (!std::isfinite(key.mTime) || !sc.positions.back().allFinite()) return NonFinite(where);
    }
    for (unsigned k = 0; k < ch.mNumRotationKeys; ++k) {
      const aiQuatKey& key = ch.mRotationKeys[k];
      sc.rotation_times.push_back(key.mTime);
      sc.rotations.emplace_back(key.mValue.w, key.mValue.x, key.mValue.y, key.mValue.z);
      if (!std::isfinite(key.mTime) || !sc.rotations.back().coeffs().allFinite())
        return NonFinite(where);
    }
    for (unsigned k = 0; k < ch.mNumScalingKeys; ++k) {
      const aiVectorKey& key = ch.mScalingKeys[k];
      sc.scaling_times.push_back(key.mTime);
      sc.scalings.emplace_back(key.mValue.x, key.mValue.y, key.mValue.z);
      if (!std::isfinite(key.mTime) || !sc.scalings.back().allFinite()) return NonFinite(where);
    }
    out.channels.push_back(std::move(sc));
  }
  return Status::Ok();
}

Status CopyScene(const aiScene& ai, Format format, Scene& scene) {
  scene.format = format;
  if (ai.mRootNode == nullptr) return DataLoss("the file has no node hierarchy");
  if (Status s = CopyNodes(ai, scene); !s.ok()) return s;
  scene.meshes.resize(ai.mNumMeshes);
  for (unsigned m = 0; m < ai.mNumMeshes; ++m) {
    if (Status s = CopyMesh(ai, *ai.mMeshes[m], format, scene.meshes[m]); !s.ok()) return s;
  }
  scene.animations.resize(ai.mNumAnimations);
  for (unsigned a = 0; a < ai.mNumAnimations; ++a) {
    if (Status s = CopyAnimation(*ai.mAnimations[a], scene.animations[a]); !s.ok()) return s;
  }
  return Status::Ok();
}

bool ListsExtension(const aiImporterDesc* desc, const std::string& wanted) {
  if (desc == nullptr || desc->mFileExtensions == nullptr) return false;
  std::istringstream extensions(desc->mFileExtensions);
  std::string e;
  while (extensions >> e) {
    if (e == wanted) return true;
  }
  return false;
}

// Leaves only the importers that register `extension` (Assimp 5.2 picks a reader by
// content among all 48 otherwise).
void RestrictImporters(Assimp::Importer& importer, const std::string& extension) {
  std::vector<Assimp::BaseImporter*> others;
  for (size_t i = 0; i < importer.GetImporterCount(); ++i) {
    Assimp::BaseImporter* reader = importer.GetImporter(i);
    if (reader != nullptr && !ListsExtension(reader->GetInfo(), extension))
      others.push_back(reader);
  }
  for (Assimp::BaseImporter* reader : others) {
    // UnregisterLoader hands ownership back to us.
    if (importer.UnregisterLoader(reader) == AI_SUCCESS) delete reader;
  }
}

std::string RefusedList(const MemoryIoSystem& io) { return QuotedList(io.refused()); }

}  // namespace

StatusOr<Scene> ImportScene(const std::string& name, const std::string& bytes, Format format,
                            const FileResolver& resolver) {
  if (format == Format::kCollada) {
    if (Status s = CheckColladaIndices(bytes); !s.ok()) {
      return Status(s.code(), Quote(name) + ": " + s.message());
    }
  }
  try {
    Assimp::Importer importer;
    RestrictImporters(importer, AssimpExtension(format));
    // The importer owns the IO system and deletes it with itself.
    auto* io = new MemoryIoSystem(name, bytes, resolver);
    importer.SetIOHandler(io);
    importer.SetPropertyBool(AI_CONFIG_IMPORT_FBX_READ_TEXTURES, false);
    importer.SetPropertyBool(AI_CONFIG_IMPORT_FBX_READ_CAMERAS, false);
    importer.SetPropertyBool(AI_CONFIG_IMPORT_FBX_READ_LIGHTS, false);
    // The SMD reader would look for "<file>/<name>_animation.txt", a path we refuse.
    importer.SetPropertyBool(AI_CONFIG_IMPORT_SMD_LOAD_ANIMATION_LIST, false);
    importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE,
                                aiPrimitiveType_POINT | aiPrimitiveType_LINE);
    const unsigned flags = aiProcess_ValidateDataStructure | aiProcess_Triangulate |
                           aiProcess_SortByPType | aiProcess_JoinIdenticalVertices |
                           aiProcess_GenSmoothNormals;
    const aiScene* ai = importer.ReadFile(name, flags);
    const std::string refused = RefusedList(*io);
    if (ai == nullptr) {
      const std::string error = importer.GetErrorString();
      if (!refused.empty()) {
        return InvalidArgument(Quote(name) + " references " + refused +
                               ", which is not among the uploaded files (references may only "
                               "name uploaded files, without directories); Assimp: " +
                               error);
      }
      if (error.find("No suitable reader") != std::string::npos) {
        // The format's reader refused the content (its own signature check failed).
        return DataLoss(Quote(name) + " could not be parsed as " + FormatName(format) +
                        " (truncated or corrupted?)");
      }
      return DataLoss("Assimp could not read " + Quote(name) + " as " + FormatName(format) + ": " +
                      (error.empty() ? std::string("no reason given") : error));
    }
    Scene scene;
    if (Status s = CopyScene(*ai, format, scene); !s.ok()) return s;
    if (!refused.empty()) {
      scene.warnings.push_back("references not among the uploaded files were ignored: " + refused);
    }
    return scene;
  } catch (const std::bad_alloc&) {
    return DataLoss(Quote(name) + " asks for more memory than is available (corrupted sizes?)");
  } catch (const std::exception& e) {
    return DataLoss("Assimp failed on " + Quote(name) + ": " + e.what());
  } catch (...) {
    return DataLoss("Assimp failed on " + Quote(name) + " with an unknown exception");
  }
}

}  // namespace motionlod::io
