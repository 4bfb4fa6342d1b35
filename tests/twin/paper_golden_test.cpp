// The paper scene's datasets must not change when field effects are added: small runs of each protocol on
// the default scene, compared bit for bit against values recorded before the field work (commit f31ed67).
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "ruffini/twin/protocols.h"

#include "fixtures.h"

namespace ruffini::twin {
namespace {

// FNV-1a over every field of every frame, in order.
struct Digest {
  std::uint64_t h = 1469598103934665603ull;
  std::uint64_t frames = 0;
  std::vector<dataset::Frame> kept;  // a few frames for readable failure messages
  void Add(const void* p, std::size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  }
  void operator()(std::span<const dataset::Frame> fs) {
    for (const auto& f : fs) {
      Add(f.wavelength_nm.data(), sizeof(double) * f.wavelength_nm.size());
      Add(&f.t_s, sizeof f.t_s);
      Add(&f.serial, sizeof f.serial);
      Add(&f.flags, sizeof f.flags);
      Add(&f.force_n, sizeof f.force_n);
      Add(&f.true_force_n, sizeof f.true_force_n);
      Add(&f.y_mm, sizeof f.y_mm);
      Add(&f.r_deg, sizeof f.r_deg);
      Add(&f.indentation, sizeof f.indentation);
      if (frames == 300 || frames == 1000) kept.push_back(f);
      ++frames;
    }
  }
};

std::string Show(const Digest& d) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "frames %llu hash 0x%016llx", static_cast<unsigned long long>(d.frames),
                static_cast<unsigned long long>(d.h));
  return buf;
}

// Values recorded on commit f31ed67 (before the field effects) with this same digest. If one of these fails,
// the paper scene's datasets changed: either the change is intended (and the README's numbers need
// re-measuring) or the field work leaked into the paper path.
TEST(PaperSceneUnchanged, PaperProtocol) {
  PaperProtocol p;
  p.indentations = 3;
  Digest d;
  RunPaper(fixtures::DefaultTwin(), fixtures::DefaultScene(), p, 7, [&](auto f) { d(f); });
  EXPECT_EQ(d.frames, 3181u);
  ASSERT_EQ(d.kept.size(), 2u);
  EXPECT_EQ(d.kept[0].wavelength_nm[3], 0x1.803a20c8e8c14p+10);
  EXPECT_EQ(d.kept[0].force_n, -0x1p-8f);
  EXPECT_EQ(d.kept[0].true_force_n, 0.0f);
  EXPECT_EQ(d.kept[1].wavelength_nm[3], 0x1.803a1c15bcf73p+10);
  EXPECT_EQ(d.kept[1].force_n, 0x1.72p+0f);
  EXPECT_EQ(d.kept[1].true_force_n, 0x1.725548p+0f);
  EXPECT_EQ(d.kept[1].y_mm, 0x1.57987cp+6f);
  EXPECT_EQ(d.kept[1].r_deg, 0x1.5600d6p+6f);
  EXPECT_EQ(d.kept[1].indentation, 0);
  EXPECT_EQ(d.h, 0x3b3af3a1685834c5ull) << Show(d);
}

TEST(PaperSceneUnchanged, VonFreyAndReceptiveField) {
  VonFreyProtocol v;
  v.subjects = 1;
  v.sites = 2;
  Digest vf;
  RunVonFrey(fixtures::DefaultTwin(), v, 7, [&](auto f) { vf(f); });
  EXPECT_EQ(vf.frames, 1600u);
  EXPECT_EQ(vf.h, 0x032ffd31e5a3c4beull) << Show(vf);
  ReceptiveFieldProtocol rf;
  rf.step_mm = 20.0;
  Digest rd;
  RunReceptiveField(fixtures::DefaultTwin(), fixtures::DefaultScene(), rf, 7, [&](auto f) { rd(f); });
  EXPECT_EQ(rd.frames, 1071u);
  ASSERT_EQ(rd.kept.size(), 2u);
  EXPECT_EQ(rd.kept[0].wavelength_nm[3], 0x1.803aa14d6cc02p+10);
  EXPECT_EQ(rd.kept[1].wavelength_nm[3], 0x1.803a1b289125fp+10);
  EXPECT_EQ(rd.h, 0x22c8f3d3556dd933ull) << Show(rd);
}

}  // namespace
}  // namespace ruffini::twin
