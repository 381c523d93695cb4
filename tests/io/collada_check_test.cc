#include "io/collada_check.h"

#include <gtest/gtest.h>

#include <string>

#include "io/asset.h"
#include "test_util.h"

namespace motionlod::io {
namespace {

// A skin over a 3-position mesh with 2 joints; `v` and `vcount` are the weights.
std::string Skin(const std::string& vcount, const std::string& v,
                 const std::string& vertex_count = "3", const std::string& weights_declared = "2") {
  return R"(<?xml version="1.0"?>
<!-- a comment with <tags> inside -->
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
<library_geometries><geometry id="mesh"><mesh>
  <source id="pos"><float_array id="pos-array" count="9">0 0 0 1 0 0 0 1 0</float_array>
    <technique_common><accessor source="#pos-array" count="3" stride="3"/></technique_common></source>
  <vertices id="verts"><input semantic="POSITION" source="#pos"/></vertices>
</mesh></geometry></library_geometries>
<library_controllers><controller id="skin"><skin source="#mesh">
  <bind_shape_matrix>1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1</bind_shape_matrix>
  <source id="names"><Name_array id="names-array" count="2">a b</Name_array>
    <technique_common><accessor source="#names-array" count="2"/></technique_common></source>
  <source id="binds"><float_array id="binds-array" count="32">1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1</float_array>
    <technique_common><accessor source="#binds-array" count="2" stride="16"/></technique_common></source>
  <source id="weights"><float_array id="weights-array" count=")" +
         weights_declared + R"(">1 0.5</float_array>
    <technique_common><accessor source="#weights-array" count=")" +
         weights_declared + R"("/></technique_common></source>
  <joints><input semantic="JOINT" source="#names"/><input semantic="INV_BIND_MATRIX" source="#binds"/></joints>
  <vertex_weights count=")" +
         vertex_count + R"(">
    <input semantic="JOINT" source="#names" offset="0"/><input semantic="WEIGHT" source="#weights" offset="1"/>
    <vcount>)" +
         vcount + R"(</vcount><v>)" + v + R"(</v>
  </vertex_weights>
</skin></controller></library_controllers>
</COLLADA>)";
}

TEST(CheckColladaIndices, AcceptsConsistentSkins) {
  EXPECT_TRUE(CheckColladaIndices(Skin("1 2 1", "0 0 0 1 1 1 1 0")).ok());
}

TEST(CheckColladaIndices, RejectsJointIndexPastTheJointNames) {
  const Status s = CheckColladaIndices(Skin("1 2 1", "0 0 0 1 7 1 1 0"));
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_NE(s.message().find("joint 7"), std::string::npos) << s.message();
}

TEST(CheckColladaIndices, RejectsWeightIndexPastTheWeights) {
  EXPECT_EQ(CheckColladaIndices(Skin("1 2 1", "0 0 0 1 1 9 1 0")).code(), StatusCode::kDataLoss);
}

TEST(CheckColladaIndices, RejectsCountsThatOverrunTheIndexList) {
  EXPECT_EQ(CheckColladaIndices(Skin("1 2 4", "0 0 0 1 1 1 1 0")).code(), StatusCode::kDataLoss);
  EXPECT_EQ(CheckColladaIndices(Skin("1 2", "0 0 0 1 1 1")).code(),
            StatusCode::kDataLoss);  // 3 declared
  EXPECT_EQ(CheckColladaIndices(Skin("1 -2 1", "0 0 0 1 1 1 1 0")).code(), StatusCode::kDataLoss);
}

TEST(CheckColladaIndices, RejectsFewerWeightedVerticesThanPositions) {
  EXPECT_EQ(CheckColladaIndices(Skin("1 2", "0 0 0 1 1 1", "2")).code(), StatusCode::kDataLoss);
}

TEST(CheckColladaIndices, RejectsAccessorsPastTheirArrays) {
  EXPECT_EQ(CheckColladaIndices(Skin("1 2 1", "0 0 0 1 1 1 1 0", "3", "5")).code(),
            StatusCode::kDataLoss);
}

TEST(CheckColladaIndices, RejectsMalformedXml) {
  EXPECT_EQ(CheckColladaIndices("<COLLADA><a></b></COLLADA>").code(), StatusCode::kDataLoss);
  EXPECT_EQ(CheckColladaIndices("<COLLADA><a>").code(), StatusCode::kDataLoss);
  EXPECT_EQ(CheckColladaIndices("<COLLADA><!-- open").code(), StatusCode::kDataLoss);
  EXPECT_EQ(CheckColladaIndices("<COLLADA a=b/>").code(), StatusCode::kDataLoss);
}

TEST(CheckColladaIndices, StormtrooperPassesAndACorruptedWeightIndexIsCaught) {
  MOTIONLOD_REQUIRE_DATA();
  std::string bytes = testing::ReadBytes(testing::DataDir() / "characters/stormtrooper.dae");
  EXPECT_TRUE(CheckColladaIndices(bytes).ok());
  // The byte flip that crashed Assimp 5.2.5: one joint index of <v> becomes 68 (of 52).
  const size_t v = bytes.find("<v>");
  ASSERT_NE(v, std::string::npos);
  bytes.replace(v + 3, 1, "68");
  const StatusOr<std::shared_ptr<const Asset>> asset = LoadAsset({{"stormtrooper.dae", bytes}});
  ASSERT_FALSE(asset.ok());
  EXPECT_EQ(asset.status().code(), StatusCode::kDataLoss);
}

}  // namespace
}  // namespace motionlod::io
