// The scene's root reader: the file's shape, the patches' paths, and which keys belong to which part.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

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
    // shipped model; the upper-arm patches name the shipped model itself.
    const std::string model = p.name.rfind("forearm_", 0) == 0 ? "cobot-" + p.name + ".rmodel" : "forearm.rmodel";
    EXPECT_EQ(fs::path(p.model_path), (fs::path(RUFFINI_SOURCE_DIR "/config/models") / model).lexically_normal());
    EXPECT_TRUE(p.entry.Has("mount") && p.entry.Has("region"));
  }
  EXPECT_EQ(s.FindPatch("forearm_b"), &s.patches[1]);
  EXPECT_EQ(s.FindPatch("hand"), nullptr);
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
