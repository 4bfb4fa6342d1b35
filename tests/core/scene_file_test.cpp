// The scene's root reader: the file's shape, the patches' paths, and which keys belong to which part.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <unistd.h>

#include <yaml-cpp/yaml.h>

#include "ruffini/error.h"
#include "ruffini/scene_file.h"

namespace ruffini {
namespace {

namespace fs = std::filesystem;

TEST(SceneFile, TheCobotScene) {
  const SceneFile s = LoadSceneFile(RUFFINI_SOURCE_DIR "/config/scenes/cobot.yaml");
  EXPECT_EQ(s.name, "cobot");
  ASSERT_EQ(s.patches.size(), 4u);
  EXPECT_TRUE(s.robot && s.twin && s.safety);
  for (const auto& p : s.patches) {
    EXPECT_EQ(fs::path(p.spec_path), fs::path(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml").lexically_normal());
    // The forearm patches share a seam and carry their own coverage maps (docs/coverage.md): copies of the
    // shipped model; the upper-arm patches share one copy (same cast, every edge free), and every copy carries
    // the two-touch check (stop 33).
    const std::string model =
        p.name.rfind("forearm_", 0) == 0 ? "cobot-" + p.name + ".rmodel" : "cobot-upper_arm.rmodel";
    EXPECT_EQ(fs::path(p.model_path), (fs::path(RUFFINI_SOURCE_DIR "/config/models") / model).lexically_normal());
    EXPECT_TRUE(p.entry.Has("mount") && p.entry.Has("region"));
  }
  EXPECT_EQ(s.FindPatch("forearm_b"), &s.patches[1]);
  EXPECT_EQ(s.FindPatch("hand"), nullptr);
}

// The demo's field scenes (issue 17) are cobot.yaml with each patch its own cast and model and field effects:
// the robot, every patch's spec, mount and region, and the safety section stay cobot.yaml's, so the demo checks
// the same thresholds and deadlines on the same arm (the coverage claim is the casts' own maps');
// cobot-field-gradient.yaml is cobot-field.yaml plus the
// temperature field and nothing else.
TEST(SceneFile, TheFieldScenesAreTheCobotWithTheirOwnCastsModelsAndEffects) {
  const std::string dir = RUFFINI_SOURCE_DIR "/config/scenes/";
  const YAML::Node lab = YAML::LoadFile(dir + "cobot.yaml");
  const YAML::Node field = YAML::LoadFile(dir + "cobot-field.yaml");
  const YAML::Node gradient = YAML::LoadFile(dir + "cobot-field-gradient.yaml");
  const auto dump = [](const YAML::Node& n) { return YAML::Dump(n); };
  for (const YAML::Node& f : {field, gradient}) {
    EXPECT_EQ(f["name"].as<std::string>(), lab["name"].as<std::string>());
    EXPECT_EQ(dump(f["robot"]), dump(lab["robot"]));
    // The safety section is the lab's but for the coverage claim: these casts' own maps guarantee a larger
    // press factor than cast 0's (never a smaller one: a field scene does not claim more than the lab), and the
    // gradient scene claims nothing (below).
    YAML::Node safety = YAML::Clone(f["safety"]), lab_safety = YAML::Clone(lab["safety"]);
    EXPECT_GE(safety["coverage"]["press_factor"].as<double>(), lab_safety["coverage"]["press_factor"].as<double>());
    // And no larger than those maps measured (the worst covered point needs 4 N = 2.67 x 1.5 N; 2.5 is refused:
    // cli.check_scene_cobot_field_refuses_a_smaller_press_factor). A larger factor would promise less than the
    // maps show: change it with a new measurement, here and in config/models/README.md (review 8).
    EXPECT_LE(safety["coverage"]["press_factor"].as<double>(), 2.67);
    const bool claims_nothing = f["twin"]["effects"]["temperature"]["gradient"].IsDefined();  // the gradient scene
    for (YAML::Node* n : {&safety, &lab_safety}) {
      (*n)["coverage"].remove("press_factor");
      (*n)["coverage"].remove("source");
      if (claims_nothing) (*n)["coverage"].remove("accepted_uncovered");
    }
    EXPECT_EQ(dump(safety), dump(lab_safety));
    ASSERT_EQ(f["patches"].size(), lab["patches"].size());
    for (std::size_t i = 0; i < lab["patches"].size(); ++i) {
      for (const char* key : {"name", "spec", "mount", "region"}) {
        EXPECT_EQ(dump(f["patches"][i][key]), dump(lab["patches"][i][key])) << key;
      }
      EXPECT_EQ(f["patches"][i]["model"].as<std::string>(),
                "../models/cobot-field-" + lab["patches"][i]["name"].as<std::string>() + ".rmodel");
    }
  }
  EXPECT_EQ(dump(gradient["patches"]), dump(field["patches"]));
  // The same safety section but for the coverage claim: the casts' maps were measured without the temperature
  // field, and a map is bound to every twin parameter it was measured with, so the gradient scene claims nothing.
  {
    YAML::Node g = YAML::Clone(gradient["safety"]), f = YAML::Clone(field["safety"]);
    g.remove("coverage");
    f.remove("coverage");
    EXPECT_EQ(dump(g), dump(f));
    const YAML::Node bands = gradient["safety"]["coverage"]["accepted_uncovered"];
    ASSERT_EQ(bands.size(), 1u);
    EXPECT_EQ(bands[0]["y_mm"][0].as<double>(), 0.0);
    EXPECT_EQ(bands[0]["y_mm"][1].as<double>(), 150.0);
    EXPECT_EQ(bands[0]["r_deg"][0].as<double>(), 0.0);
    EXPECT_EQ(bands[0]["r_deg"][1].as<double>(), 145.0);
  }
  EXPECT_FALSE(field["twin"]["effects"]["temperature"]["gradient"]);
  ASSERT_TRUE(gradient["twin"]["effects"]["temperature"]["gradient"]);
  YAML::Node without = YAML::Clone(gradient["twin"]);
  without["effects"]["temperature"].remove("gradient");
  EXPECT_EQ(dump(without), dump(field["twin"]));
  // Four casts, one per patch, none of them the lab's (0) or docs/experiments/field.md's test casts (1, 2).
  ASSERT_EQ(field["twin"]["casts"].size(), 4u);
  std::set<long> seeds;
  for (const auto& c : field["twin"]["casts"]) seeds.insert(c["skin_sample"].as<long>());
  EXPECT_EQ(seeds.size(), 4u);
  for (long s : seeds) EXPECT_GT(s, 2) << s;
}

TEST(SceneFile, TheBenchSceneHasNoRobotOrSafety) {
  const SceneFile s = LoadSceneFile(RUFFINI_SOURCE_DIR "/config/scenes/forearm.yaml");
  EXPECT_EQ(s.name, "forearm-bench");
  ASSERT_EQ(s.patches.size(), 1u);
  EXPECT_TRUE(s.twin.has_value());
  EXPECT_FALSE(s.robot || s.safety);
}

class BadSceneFile : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::path(::testing::TempDir()) / (std::to_string(::getpid()) + "_ruffini_scene_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string Message(const std::string& text) const {
    const std::string path = (dir_ / "s.yaml").string();
    std::ofstream(path) << text;
    try {
      (void)LoadSceneFile(path);
    } catch (const InputError& e) {
      return std::string(e.what()).substr(path.size());
    }
    return "(no error)";
  }
  const std::string spec_ = RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml";
  fs::path dir_;
};

TEST_F(BadSceneFile, Messages) {
  const std::string patch = "patches:\n  - name: a\n    spec: " + spec_ + "\n";
  EXPECT_EQ(Message("name: t\n" + patch + "robto: {urdf: x.urdf}\n"), ":5:1: 'robto' is not a known key here");
  EXPECT_EQ(Message("name: t\n" + patch + "    colour: red\n"), ":5:5: 'patches[0].colour' is not a known key here");
  EXPECT_EQ(Message("name: t\n" + patch + "  - name: a\n    spec: " + spec_ + "\n"),
            ":5:5: 'patches[1].name' (a) is used by two patches; patch names must be unique");
  EXPECT_EQ(Message("name: t\npatches: []\n"), ":2:1: 'patches' must list at least one patch");
  EXPECT_EQ(Message("name: t\n" + patch + "robot: [srs7]\n"), ":5:1: 'robot' must be a mapping");
  EXPECT_EQ(Message("name: t\n" + patch + "    model: none.rmodel\n"),
            ":5:5: 'patches[0].model' (none.rmodel) names a file that does not exist (" + (dir_ / "none.rmodel").string() +
                ")");
}

}  // namespace
}  // namespace ruffini
