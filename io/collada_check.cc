#include "io/collada_check.h"

#include <charconv>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "io/text.h"

namespace motionlod::io {
namespace {

constexpr int kMaxDepth = 4096;

struct Element {
  std::string_view name;  // local name (namespace prefix removed)
  std::vector<std::pair<std::string_view, std::string_view>> attributes;
  std::string text;  // character data directly inside (CDATA included)
  std::vector<int> children;
  int parent = -1;

  std::string_view Attribute(std::string_view key) const {
    for (const auto& [k, v] : attributes) {
      if (k == key) return v;
    }
    return {};
  }
};

// A small non-validating XML reader: elements, attributes, text, comments, CDATA,
// processing instructions and a DOCTYPE (skipped). Entities are left as they are.
class Document {
 public:
  Status Parse(std::string_view xml) {
    xml_ = xml;
    std::vector<int> open;
    size_t pos = 0;
    while (pos < xml.size()) {
      const size_t lt = xml.find('<', pos);
      if (!open.empty())
        AppendText(open.back(),
                   xml.substr(pos, (lt == std::string_view::npos ? xml.size() : lt) - pos));
      if (lt == std::string_view::npos) break;
      pos = lt;
      if (xml.compare(pos, 4, "<!--") == 0) {
        if (!SkipPast(pos, "-->")) return Malformed("an unterminated comment");
      } else if (xml.compare(pos, 9, "<![CDATA[") == 0) {
        const size_t end = xml.find("]]>", pos + 9);
        if (end == std::string_view::npos) return Malformed("an unterminated CDATA section");
        if (!open.empty()) AppendText(open.back(), xml.substr(pos + 9, end - pos - 9));
        pos = end + 3;
      } else if (xml.compare(pos, 2, "<?") == 0) {
        if (!SkipPast(pos, "?>")) return Malformed("an unterminated processing instruction");
      } else if (xml.compare(pos, 2, "<!") == 0) {
        int brackets = 0;
        size_t p = pos + 2;
        for (; p < xml.size(); ++p) {
          if (xml[p] == '[') ++brackets;
          if (xml[p] == ']') --brackets;
          if (xml[p] == '>' && brackets <= 0) break;
        }
        if (p >= xml.size()) return Malformed("an unterminated declaration");
        pos = p + 1;
      } else if (xml.compare(pos, 2, "</") == 0) {
        const size_t gt = xml.find('>', pos);
        if (gt == std::string_view::npos) return Malformed("an unterminated end tag");
        const std::string_view name = LocalName(Trim(xml.substr(pos + 2, gt - pos - 2)));
        if (open.empty() || elements_[open.back()].name != name)
          return Malformed("mismatched end tag </" + std::string(name) + ">");
        open.pop_back();
        pos = gt + 1;
      } else {
        Status s = ReadStartTag(pos, open);
        if (!s.ok()) return s;
      }
    }
    if (!open.empty())
      return Malformed("unclosed <" + std::string(elements_[open.back()].name) + ">");
    return Status::Ok();
  }

  const std::vector<Element>& elements() const { return elements_; }

 private:
  static std::string_view Trim(std::string_view s) {
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
    return s;
  }
  static std::string_view LocalName(std::string_view name) {
    const size_t colon = name.rfind(':');
    return colon == std::string_view::npos ? name : name.substr(colon + 1);
  }
  static Status Malformed(const std::string& what) {
    return DataLoss("the COLLADA XML is malformed: " + what);
  }
  bool SkipPast(size_t& pos, std::string_view end) {
    const size_t at = xml_.find(end, pos);
    if (at == std::string_view::npos) return false;
    pos = at + end.size();
    return true;
  }
  void AppendText(int element, std::string_view text) {
    // Only leaf-ish data elements matter; skip pure white space.
    if (Trim(text).empty()) return;
    elements_[element].text.append(text);
    elements_[element].text.push_back(' ');
  }

  Status ReadStartTag(size_t& pos, std::vector<int>& open) {
    const std::string_view xml = xml_;
    size_t p = pos + 1;
    const size_t name_begin = p;
    while (p < xml.size() && !std::isspace(static_cast<unsigned char>(xml[p])) && xml[p] != '>' &&
           xml[p] != '/')
      ++p;
    if (p == name_begin || p >= xml.size()) return Malformed("a broken start tag");
    Element element;
    element.name = LocalName(xml.substr(name_begin, p - name_begin));
    bool self_closing = false;
    while (true) {
      while (p < xml.size() && std::isspace(static_cast<unsigned char>(xml[p]))) ++p;
      if (p >= xml.size()) return Malformed("an unterminated start tag");
      if (xml[p] == '>') {
        ++p;
        break;
      }
      if (xml[p] == '/') {
        if (p + 1 >= xml.size() || xml[p + 1] != '>')
          return Malformed("a broken empty-element tag");
        self_closing = true;
        p += 2;
        break;
      }
      const size_t key_begin = p;
      while (p < xml.size() && xml[p] != '=' && xml[p] != '>' &&
             !std::isspace(static_cast<unsigned char>(xml[p])))
        ++p;
      const std::string_view key = xml.substr(key_begin, p - key_begin);
      while (p < xml.size() && std::isspace(static_cast<unsigned char>(xml[p]))) ++p;
      if (p >= xml.size() || xml[p] != '=') return Malformed("an attribute without a value");
      ++p;
      while (p < xml.size() && std::isspace(static_cast<unsigned char>(xml[p]))) ++p;
      if (p >= xml.size() || (xml[p] != '"' && xml[p] != '\''))
        return Malformed("an unquoted attribute");
      const char quote = xml[p];
      const size_t value_end = xml.find(quote, p + 1);
      if (value_end == std::string_view::npos) return Malformed("an unterminated attribute");
      element.attributes.emplace_back(LocalName(key), xml.substr(p + 1, value_end - p - 1));
      p = value_end + 1;
    }
    element.parent = open.empty() ? -1 : open.back();
    const int index = static_cast<int>(elements_.size());
    if (element.parent >= 0) elements_[element.parent].children.push_back(index);
    elements_.push_back(std::move(element));
    if (!self_closing) {
      if (open.size() >= kMaxDepth) return Malformed("elements nested too deeply");
      open.push_back(index);
    }
    pos = p;
    return Status::Ok();
  }

  std::string_view xml_;
  std::vector<Element> elements_;
};

// Whitespace-separated tokens of `text`.
std::vector<std::string_view> Tokens(std::string_view text) {
  std::vector<std::string_view> out;
  size_t p = 0;
  while (p < text.size()) {
    while (p < text.size() && std::isspace(static_cast<unsigned char>(text[p]))) ++p;
    const size_t begin = p;
    while (p < text.size() && !std::isspace(static_cast<unsigned char>(text[p]))) ++p;
    if (p > begin) out.push_back(text.substr(begin, p - begin));
  }
  return out;
}

// A non-negative integer; -1 when the text is not one (or is absurdly large).
int64_t Count(std::string_view text) {
  int64_t value = -1;
  const auto result = std::from_chars(text.data(), text.data() + text.size(), value);
  if (result.ec != std::errc() || result.ptr != text.data() + text.size() || value < 0 ||
      value > (int64_t{1} << 40)) {
    return -1;
  }
  return value;
}

bool IsInteger(std::string_view token, bool allow_sign) {
  if (allow_sign && !token.empty() && (token.front() == '-' || token.front() == '+'))
    token.remove_prefix(1);
  if (token.empty() || token.size() > 18) return false;
  for (char c : token) {
    if (c < '0' || c > '9') return false;
  }
  return true;
}

bool IsReal(std::string_view token) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  double value = 0;
  const auto result = std::from_chars(token.data(), token.data() + token.size(), value);
  return result.ec == std::errc() && result.ptr == token.data() + token.size();
}

std::string_view StripHash(std::string_view reference) {
  if (!reference.empty() && reference.front() == '#') reference.remove_prefix(1);
  return reference;
}

struct SourceInfo {
  int64_t count = 0;   // accessor count (entries)
  int64_t values = 0;  // values in the array
};

class Checker {
 public:
  explicit Checker(const Document& doc) : doc_(doc) {
    const auto& elements = doc.elements();
    for (size_t i = 0; i < elements.size(); ++i) {
      const std::string_view id = elements[i].Attribute("id");
      if (!id.empty()) by_id_.emplace(id, static_cast<int>(i));
    }
  }

  Status Run() {
    const auto& elements = doc_.elements();
    for (size_t i = 0; i < elements.size(); ++i) {
      const Element& e = elements[i];
      if (e.name.size() > 6 && e.name.substr(e.name.size() - 6) == "_array" &&
          !e.Attribute("count").empty()) {
        const int64_t declared = Count(e.Attribute("count"));
        const int64_t present = static_cast<int64_t>(Tokens(e.text).size());
        if (declared < 0 || present < declared) {
          return DataLoss("COLLADA array " + Quote(e.Attribute("id")) + " declares " +
                          std::string(e.Attribute("count")) + " values but holds " +
                          std::to_string(present));
        }
      }
      if (e.name == "p" || e.name == "vcount" || e.name == "v" || e.name == "h" ||
          e.name == "int_array" || e.name == "float_array") {
        // Assimp's number readers do not advance over a malformed token: a stray character
        // in an index list makes it append zeros until memory runs out.
        const bool real = e.name == "float_array";
        const bool sign = real || e.name == "int_array";
        for (std::string_view token : Tokens(e.text)) {
          if (!(real ? IsReal(token) : IsInteger(token, sign))) {
            return DataLoss("the COLLADA <" + std::string(e.name) + "> element holds " +
                            Quote(token.substr(0, 32)) + ", which is not a number");
          }
        }
      }
      if (e.name == "accessor") {
        StatusOr<SourceInfo> info = Accessor(static_cast<int>(i));
        if (!info.ok()) return info.status();
      }
      if (e.name == "skin") {
        if (Status s = Skin(static_cast<int>(i)); !s.ok()) return s;
      }
    }
    return Status::Ok();
  }

 private:
  const Element* Child(int element, std::string_view name) const {
    for (int c : doc_.elements()[element].children) {
      if (doc_.elements()[c].name == name) return &doc_.elements()[c];
    }
    return nullptr;
  }
  int Index(const Element* e) const { return static_cast<int>(e - doc_.elements().data()); }

  StatusOr<SourceInfo> Accessor(int accessor) const {
    const Element& a = doc_.elements()[accessor];
    const std::string_view array_id = StripHash(a.Attribute("source"));
    const int64_t count = Count(a.Attribute("count").empty() ? "0" : a.Attribute("count"));
    const int64_t stride = Count(a.Attribute("stride").empty() ? "1" : a.Attribute("stride"));
    const int64_t offset = Count(a.Attribute("offset").empty() ? "0" : a.Attribute("offset"));
    if (count < 0 || stride < 1 || offset < 0) {
      return DataLoss("a COLLADA accessor of " + Quote(array_id) +
                      " has a bad count, stride or offset");
    }
    const auto it = by_id_.find(array_id);
    int64_t values = 0;
    if (it != by_id_.end()) {
      const Element& array = doc_.elements()[it->second];
      values = Count(array.Attribute("count").empty() ? "0" : array.Attribute("count"));
    }
    if (count > 0 && offset + (count - 1) * stride + 1 > values) {
      return DataLoss("a COLLADA accessor reads " + std::to_string(count) + " entries of stride " +
                      std::to_string(stride) + " from " + Quote(array_id) + ", which holds " +
                      std::to_string(values) + " values");
    }
    return SourceInfo{count, values};
  }

  // The accessor of <source id=reference>.
  StatusOr<SourceInfo> Source(std::string_view reference, const char* role) const {
    const auto it = by_id_.find(StripHash(reference));
    if (it == by_id_.end())
      return DataLoss("a COLLADA skin refers to the missing " + std::string(role) + " source " +
                      Quote(reference));
    const Element* technique = Child(it->second, "technique_common");
    const Element* accessor = technique != nullptr ? Child(Index(technique), "accessor") : nullptr;
    if (accessor == nullptr)
      return DataLoss("the COLLADA source " + Quote(reference) + " has no accessor");
    return Accessor(Index(accessor));
  }

  Status Skin(int skin) const {
    const Element* joints = Child(skin, "joints");
    const Element* weights = Child(skin, "vertex_weights");
    if (joints == nullptr || weights == nullptr)
      return Status::Ok();  // Assimp rejects these itself
    StatusOr<SourceInfo> joint_names = SourceInfo{}, inverse_binds = SourceInfo{};
    for (int c : joints->children) {
      const Element& input = doc_.elements()[c];
      if (input.name != "input") continue;
      if (input.Attribute("semantic") == "JOINT")
        joint_names = Source(input.Attribute("source"), "joint");
      if (input.Attribute("semantic") == "INV_BIND_MATRIX")
        inverse_binds = Source(input.Attribute("source"), "bind matrix");
      if (!joint_names.ok()) return joint_names.status();
      if (!inverse_binds.ok()) return inverse_binds.status();
    }
    // Assimp makes one bone per joint name and reads a bind matrix for each.
    if (inverse_binds->count < joint_names->values || joint_names->count < joint_names->values) {
      return DataLoss("a COLLADA skin names " + std::to_string(joint_names->values) +
                      " joints but has " + std::to_string(inverse_binds->count) +
                      " inverse bind matrices");
    }
    int64_t stride = 0, joint_offset = -1, weight_offset = -1;
    SourceInfo joint_source, weight_source;
    for (int c : weights->children) {
      const Element& input = doc_.elements()[c];
      if (input.name != "input") continue;
      const int64_t offset =
          Count(input.Attribute("offset").empty() ? "0" : input.Attribute("offset"));
      if (offset < 0) return DataLoss("a COLLADA vertex_weights input has a bad offset");
      stride = std::max(stride, offset + 1);
      StatusOr<SourceInfo> source = Source(input.Attribute("source"), "weight");
      if (!source.ok()) return source.status();
      if (input.Attribute("semantic") == "JOINT") {
        joint_offset = offset;
        joint_source = *source;
      } else if (input.Attribute("semantic") == "WEIGHT") {
        weight_offset = offset;
        weight_source = *source;
      }
    }
    const int64_t vertices = Count(weights->Attribute("count"));
    const Element* vcount = Child(Index(weights), "vcount");
    const Element* v = Child(Index(weights), "v");
    if (vertices < 0 || vcount == nullptr || v == nullptr || joint_offset < 0 ||
        weight_offset < 0) {
      return DataLoss("a COLLADA vertex_weights element is incomplete");
    }
    const std::vector<std::string_view> counts = Tokens(vcount->text);
    const std::vector<std::string_view> pairs = Tokens(v->text);
    if (static_cast<int64_t>(counts.size()) != vertices) {
      return DataLoss("a COLLADA vertex_weights element declares " + std::to_string(vertices) +
                      " vertices but its vcount lists " + std::to_string(counts.size()));
    }
    int64_t total = 0;
    for (std::string_view c : counts) {
      const int64_t n = Count(c);
      if (n < 0) return DataLoss("a COLLADA vcount holds " + Quote(c) + ", not a count");
      total += n;
    }
    if (total * stride > static_cast<int64_t>(pairs.size())) {
      return DataLoss("a COLLADA vertex_weights element needs " + std::to_string(total * stride) +
                      " indices but its <v> holds " + std::to_string(pairs.size()));
    }
    const int64_t joint_limit = std::min(joint_source.count, joint_names->values);
    for (int64_t k = 0; k < total; ++k) {
      const int64_t joint = Count(pairs[k * stride + joint_offset]);
      const int64_t weight = Count(pairs[k * stride + weight_offset]);
      if (joint < 0 || joint >= joint_limit) {
        return DataLoss("a COLLADA vertex weight names joint " +
                        std::string(pairs[k * stride + joint_offset]) + " of " +
                        std::to_string(joint_limit));
      }
      if (weight < 0 || weight >= weight_source.count) {
        return DataLoss("a COLLADA vertex weight uses weight " +
                        std::string(pairs[k * stride + weight_offset]) + " of " +
                        std::to_string(weight_source.count));
      }
    }
    // Every position of the skinned mesh needs its vcount entry.
    const auto geometry = by_id_.find(StripHash(doc_.elements()[skin].Attribute("source")));
    if (geometry != by_id_.end()) {
      const Element* mesh = Child(geometry->second, "mesh");
      const Element* vertices_element = mesh != nullptr ? Child(Index(mesh), "vertices") : nullptr;
      if (vertices_element != nullptr) {
        for (int c : vertices_element->children) {
          const Element& input = doc_.elements()[c];
          if (input.name != "input" || input.Attribute("semantic") != "POSITION") continue;
          StatusOr<SourceInfo> positions = Source(input.Attribute("source"), "position");
          if (!positions.ok()) return positions.status();
          if (positions->count > vertices) {
            return DataLoss("a COLLADA skin weights " + std::to_string(vertices) +
                            " vertices of a mesh with " + std::to_string(positions->count) +
                            " positions");
          }
        }
      }
    }
    return Status::Ok();
  }

  const Document& doc_;
  std::unordered_map<std::string_view, int> by_id_;
};

}  // namespace

Status CheckColladaIndices(std::string_view xml) {
  Document doc;
  if (Status s = doc.Parse(xml); !s.ok()) return s;
  return Checker(doc).Run();
}

}  // namespace motionlod::io
