// Review 3 probes of the seam fusion (Fuser::PlaceOnSeams, commit ffa84c7): does a contact moved onto its seam
// keep a covariance that covers where the touch is, with confident, huge and several seams; and does the seam
// rule allocate. Tests marked "FAILED at ffa84c7" were findings and failed on that commit; all pass since the fixes.
// Review 4's probes of those fixes follow review 3's, with the same fixture.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <limits>
#include <string>
#include <vector>

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#include "../common/alloc_counter.h"
#pragma GCC diagnostic pop
#include "fixture.h"
#include "ruffini/fusion/covariance.h"
#include "ruffini/fusion/fuser.h"

namespace ruffini::fusion {
namespace {

using testing::Located;
using testing::Patch;

// fore_a (fore z 0..0.15) meets fore_b (fore 0.15..0.30) at fore_a's Y = 150 edge (a Y seam).
FusionConfig TwoOnFore(double band_mm) {
  FusionConfig c;
  c.patches = {Patch("fore_a", "fore", 0.0), Patch("fore_b", "fore", 0.15)};
  std::vector<robot::MountedSurface> surfaces;
  for (const FusionPatch& p : c.patches) surfaces.push_back({p.mount, p.extent_y_mm, p.extent_r_deg});
  for (const robot::Seam& s : robot::FindSeams(surfaces)) c.seams.push_back({s, band_mm, band_mm});
  return c;
}

struct World {
  robot::Model model = testing::TestModel();
  robot::Data fk = testing::PosesAtZero(model);
  Fuser fuser;
  FusionData data;
  explicit World(FusionConfig c) : fuser(model, std::move(c)) {}
  std::span<const BodyContact> Run(const std::vector<PatchInput>& in) {
    fuser.Update(in, fk.X_BL, data);
    return data.contacts();
  }
  // Where a surface point of `patch` is in B.
  Eigen::Vector3d Point(std::size_t patch, double y_mm, double r_deg) const {
    LiftedContact out;
    EXPECT_EQ(Lift(fuser.config().patches[patch], fk.X_BL[fuser.patch_link(patch)], Located(y_mm, r_deg),
                   fuser.config().lift, out),
              Rejection::kNone);
    return out.p_BC_m;
  }
  // The gate's statistic between a true point and the body contact holding `patch` (2 dof, tangent plane).
  double D2(std::size_t patch, const Eigen::Vector3d& truth) const {
    for (const BodyContact& b : data.contacts()) {
      if (!b.HasPatch(patch)) continue;
      return TangentMahalanobis2({b.p_BC_m, b.cov_p_BC_m2}, {truth, Eigen::Matrix3d::Zero()}, b.n_B);
    }
    return std::numeric_limits<double>::infinity();
  }
};

// FAILED at ffa84c7 (passes since the fix). Two separate touches, each decoded where it is with a confident covariance: fore_a at Y 118
// (32 mm from the seam, 4 mm sd) and fore_b at Y 10 (10 mm, 2 mm sd), both 25 mm bands. fore_a's counts as "may be
// on the seam" (32 - 2 x 4 = 24 <= 25) and is moved onto it with a sd across of 12.5 mm: its true place is then
// 2.56 sd away, outside the 95 % region (d2 6.55 > 5.99), while its own estimate covered it exactly. The doc's "the
// union of both bands lies within 2 sd" does not hold for band + 2 sd.
TEST(Review3SeamFusion, AContactAtItsBandPlusTwoSdStaysCovered) {
  World w(TwoOnFore(25));
  ASSERT_EQ(w.fuser.config().seams.size(), 1u);
  w.Run({{0, Located(118, 60, 1.0, 4.0)}, {1, Located(10, 60, 1.0, 2.0)}});
  EXPECT_EQ(w.data.counters.seam_pairs, 1u);
  EXPECT_LE(w.D2(0, w.Point(0, 118, 60)), kChi2_2dof_95) << "fore_a's touch is no longer covered";
  EXPECT_LE(w.D2(1, w.Point(1, 10, 60)), kChi2_2dof_95);
}

// FAILED at ffa84c7 (passes since the fix). A contact that says "somewhere along Y" (sd across the seam 1 m, the lift's cap) on fore_b at
// Y 140, 140 mm from the seam: MayBeOnSeam is true for any place (140 - 2 x 1000 < 25), and PlaceOnSeams replaces
// its 1 m sd across the seam with 12.5 mm: a confident contact on the seam. If the touch is where its mean says
// (Y 140), it is 11 sd away.
TEST(Review3SeamFusion, AnUncertainContactIsNotMadeConfidentOnTheSeam) {
  World w(TwoOnFore(25));
  SurfaceContact vague = Located(140, 60, 1.0);
  vague.cov_yy_mm2 = 1e6;  // 1 m sd along Y (across the Y seam)
  w.Run({{0, Located(140, 60, 1.0, 2.0)}, {1, vague}});
  EXPECT_EQ(w.data.counters.seam_pairs, 1u);
  EXPECT_LE(w.D2(1, w.Point(1, 140, 60)), kChi2_2dof_95) << "fore_b's own mean is no longer covered";
}

// Passes at ffa84c7 (uncalibrated contacts): an uncalibrated contact counts as 12.5 mm sd, so "may be on the seam"
// reaches band + 25 mm = 50 mm into fore_b (a third of its 150 mm) and such a contact is moved onto the seam.
TEST(Review3SeamFusion, AnUncalibratedContactFiftyMmAwayIsPlacedOnTheSeam) {
  World w(TwoOnFore(25));
  SurfaceContact unc = Located(49, 60, 1.0);
  unc.uncertainty_calibrated = false;
  w.Run({{0, Located(140, 60, 1.0, 2.0)}, {1, unc}});
  EXPECT_EQ(w.data.counters.seam_pairs, 1u);
  // Its mean (Y 49 of fore_b) relative to the fused contact on the seam, in sd: printed for the report.
  std::printf("uncalibrated at 49 mm: d2 to its own mean %.2f\n", w.D2(1, w.Point(1, 49, 60)));
}

// Four patches around one link (90 deg each, R = 0 turned by 0, 90, 180, 270 deg): four R seams, every patch in
// two. A contact in the middle of p0 (31 mm from both edges, sd 2 mm) "may be" on both of its seams. One probe on
// seam p3|p0 (p0's share decoded mid-patch, p3's 14 mm from the seam) and a separate touch on p1 14 mm from seam
// p0|p1: PlaceOnSeams moves p0 onto p3|p0, then again onto p0|p1 (FindSeams lists p0 r_min | p3 r_max first;
// the last seam wins), so p3's share of the probe stays alone on its seam and p0's share is fused with the other
// touch, 63 mm away. Which seam wins depends on the order of the list, not on the data.
// FAILED at ffa84c7 (p0 and p3, the one probe, were not one contact). Since the fix a patch is placed on at most
// one seam, the best-agreeing pair first: here p3's contact is at p0's Y and p1's 15 mm off along the seam (with
// both at the same Y the two pairings are equally good and either may win).
TEST(Review3SeamFusion, APatchInTwoSeamsIsPlacedOnTheOneItsPartnerIsOn) {
  FusionConfig c;
  const char* names[4] = {"p0", "p1", "p2", "p3"};
  for (int k = 0; k < 4; ++k) {
    FusionPatch p = Patch(names[k], "fore", 0.0, 40.0, 90.0 * k);
    p.extent_r_deg = 90.0;
    c.patches.push_back(p);
  }
  std::vector<robot::MountedSurface> surfaces;
  for (const FusionPatch& p : c.patches) surfaces.push_back({p.mount, p.extent_y_mm, p.extent_r_deg});
  for (const robot::Seam& s : robot::FindSeams(surfaces)) c.seams.push_back({s, 30.0, 30.0});
  for (const auto& s : c.seams) std::printf("  seam p%zu %s | p%zu %s\n", s.seam.a, robot::ToString(s.seam.edge_a), s.seam.b, robot::ToString(s.seam.edge_b));
  ASSERT_EQ(c.seams.size(), 4u);
  World w(c);
  const auto out = w.Run({{0, Located(75, 45, 1.0)}, {3, Located(75, 70, 1.0)}, {1, Located(90, 20, 1.0)}});
  std::printf("seam pairs %llu, contacts %zu\n", static_cast<unsigned long long>(w.data.counters.seam_pairs), out.size());
  bool p0_with_p3 = false;
  for (const BodyContact& b : out) p0_with_p3 = p0_with_p3 || (b.HasPatch(0) && b.HasPatch(3));
  EXPECT_TRUE(p0_with_p3) << "the probe on seam p3|p0 is split; p0's share went to seam p0|p1";
}

// Passes at ffa84c7 (a limitation, not a fault): a neighbour whose cover is 1.5 mm thicker (radius 41.5 mm vs
// 40) is not a seam (FindSeams wants the point within 1 mm of the other cylinder), so no seam rule applies there.
TEST(Review3SeamFusion, ANeighbourOfAnotherRadiusIsNoSeam) {
  std::vector<robot::MountedSurface> surfaces = {
      {Patch("a", "fore", 0.0, 40.0).mount, 150.0, 145.0}, {Patch("b", "fore", 0.0, 41.5, 145.0).mount, 150.0, 145.0}};
  EXPECT_EQ(robot::FindSeams(surfaces).size(), 0u);
  surfaces[1].mount.surface_radius_mm = 40.0;
  EXPECT_EQ(robot::FindSeams(surfaces).size(), 1u);
}

// Passes at ffa84c7: a ring of a 300 deg and a 60 deg patch has its two seams (the wrap of R is handled).
TEST(Review3SeamFusion, AWidePatchRingSeams) {
  FusionPatch wide = Patch("wide", "fore", 0.0, 40.0, 0.0);
  FusionPatch narrow = Patch("narrow", "fore", 0.0, 40.0, 300.0);
  std::vector<robot::MountedSurface> surfaces = {{wide.mount, 150.0, 300.0}, {narrow.mount, 150.0, 60.0}};
  const auto seams = robot::FindSeams(surfaces);
  std::printf("a 300 + 60 deg ring: %zu seams (2 expected)\n", seams.size());
  for (const auto& s : seams) std::printf("  %zu %s | %zu %s\n", s.a, robot::ToString(s.edge_a), s.b, robot::ToString(s.edge_b));
  EXPECT_EQ(seams.size(), 2u);
}

// FAILED at ffa84c7 (passes since the fix). Two patches side by side around the limb (a's R 145 edge on b's R 0 edge), b mounted 80 mm
// further along the limb: their covers meet along 70 mm (a's Y 80..150 = b's Y 0..70). FindSeams probes only
// the middle of each edge (a's Y 75 lies beside no b, b's Y 75 beside no a), so the seam is not found: no seam
// rule, and the twin does not make those edges `continued`.
TEST(Review3SeamFusion, ASeamAlongPartOfTheEdgesIsFound) {
  std::vector<robot::MountedSurface> surfaces = {{Patch("a", "fore", 0.0, 40.0).mount, 150.0, 145.0},
                                                 {Patch("b", "fore", 0.08, 40.0, 145.0).mount, 150.0, 145.0}};
  EXPECT_EQ(robot::FindSeams(surfaces).size(), 1u);
  surfaces[1].mount = Patch("b", "fore", 0.0, 40.0, 145.0).mount;
  EXPECT_EQ(robot::FindSeams(surfaces).size(), 1u) << "control: not shifted";
}

// Passes at ffa84c7: the seam rule (placements, mixtures) allocates nothing over 5000 updates.
TEST(Review3SeamFusion, SeamUpdatesDoNotAllocate) {
  World w(TwoOnFore(25));
  std::vector<PatchInput> in;
  in.reserve(4);
  const long n = ruffini::testing::CountAllocations([&] {
    for (int k = 0; k < 5000; ++k) {
      in.clear();
      in.push_back({0, Located(130 - (k % 20), 30 + (k % 60), 1.0)});
      in.push_back({1, Located(5 + (k % 15), 90 - (k % 50), 1.0)});
      w.fuser.Update(in, w.fk.X_BL, w.data);
    }
  });
  EXPECT_EQ(n, 0);
  EXPECT_GT(w.data.counters.seam_pairs, 0u);
  EXPECT_GT(w.data.counters.seam_mixtures, 0u);
}

// --- Review 4 (of review 3's fixes, commit 2915829): the best-partner ordering, the across-seam sd on extreme
// covariances, allocation with several seams. "FAILED at 2915829" marks its findings; all pass since the fixes.

// Four patches around one link (90 deg each): four R seams, every patch in two (as review 3's ring).
FusionConfig Ring() {
  FusionConfig c;
  const char* names[4] = {"p0", "p1", "p2", "p3"};
  for (int k = 0; k < 4; ++k) {
    FusionPatch p = Patch(names[k], "fore", 0.0, 40.0, 90.0 * k);
    p.extent_r_deg = 90.0;
    c.patches.push_back(p);
  }
  std::vector<robot::MountedSurface> surfaces;
  for (const FusionPatch& p : c.patches) surfaces.push_back({p.mount, p.extent_y_mm, p.extent_r_deg});
  for (const robot::Seam& s : robot::FindSeams(surfaces)) c.seams.push_back({s, 30.0, 30.0});
  return c;
}

// FAILED at 2915829 (passes since the fix). "A patch on several seams goes with its best-agreeing partner" (docs/fusion.md): the pairs
// are ordered by their Mahalanobis distance, which a vague contact makes small whatever it says. p0's share of a
// probe on seam p3|p0 (Y 75, sd 2 mm); p3's share 3 mm off along the seam (sd 2 mm: d2 about 1, well inside
// the gate); a separate touch on p1 near seam p0|p1, 25 mm off along it but with a 60 mm sd along Y: its d2 is
// about 0.2, so p0 goes with p1 and the probe's two shares are split (p3 alone, p0 fused with the vague touch).
TEST(Review4SeamFusion, AVaguePartnerDoesNotWinOverAnAgreeingOne) {
  World w(Ring());
  ASSERT_EQ(w.fuser.config().seams.size(), 4u);
  SurfaceContact vague = Located(100, 20, 1.0);
  vague.cov_yy_mm2 = 60.0 * 60.0;
  const auto out = w.Run({{0, Located(75, 45, 1.0)}, {3, Located(78, 70, 1.0)}, {1, vague}});
  bool p0_with_p3 = false, p0_with_p1 = false;
  for (const BodyContact& b : out) {
    p0_with_p3 = p0_with_p3 || (b.HasPatch(0) && b.HasPatch(3));
    p0_with_p1 = p0_with_p1 || (b.HasPatch(0) && b.HasPatch(1));
  }
  EXPECT_TRUE(p0_with_p3) << "p0 with p1 (the vague touch): " << p0_with_p1 << "; contacts " << out.size();
}

// Control: the same p3 and p1, p1 as sure as the others (2 mm): p0 goes with p3.
TEST(Review4SeamFusion, ControlWithASurePartnerTheAgreeingOneWins) {
  World w(Ring());
  const auto out = w.Run({{0, Located(75, 45, 1.0)}, {3, Located(78, 70, 1.0)}, {1, Located(100, 20, 1.0)}});
  bool p0_with_p3 = false;
  for (const BodyContact& b : out) p0_with_p3 = p0_with_p3 || (b.HasPatch(0) && b.HasPatch(3));
  EXPECT_TRUE(p0_with_p3);
}

// Passes: extreme but valid covariances (1e30 mm^2, what CheckContact lets through) on a seam give finite
// places and covariances (the new across-seam sd is 2 own sd + band: 1e15 mm before the lift's clamp).
TEST(Review4SeamFusion, AHugeCovarianceOnTheSeamStaysFinite) {
  World w(TwoOnFore(25));
  SurfaceContact huge = Located(10, 60, 1.0);
  huge.cov_yy_mm2 = 1e30;
  huge.cov_ss_mm2 = 1e30;
  const auto out = w.Run({{0, Located(140, 60, 1.0)}, {1, huge}});
  ASSERT_FALSE(out.empty());
  for (const BodyContact& b : out) {
    EXPECT_TRUE(b.p_BC_m.allFinite());
    EXPECT_TRUE(b.cov_p_BC_m2.allFinite());
    EXPECT_TRUE(std::isfinite(b.force_n));
  }
}

// Passes: the candidate sort with several seams (four in the ring, three contacts) allocates nothing.
TEST(Review4SeamFusion, SeveralSeamsDoNotAllocate) {
  World w(Ring());
  std::vector<PatchInput> in;
  in.reserve(4);
  const long n = ruffini::testing::CountAllocations([&] {
    for (int k = 0; k < 3000; ++k) {
      in.clear();
      in.push_back({0, Located(60 + (k % 30), 45, 1.0, 2.0 + (k % 7))});
      in.push_back({1, Located(70 + (k % 20), 10 + (k % 15), 1.0)});
      in.push_back({3, Located(80 - (k % 25), 75 + (k % 10), 1.0)});
      w.fuser.Update(in, w.fk.X_BL, w.data);
    }
  });
  EXPECT_EQ(n, 0);
  EXPECT_GT(w.data.counters.seam_pairs, 0u);
}

// FAILED at 2915829 (passes since the fix). FindSeams probes five points per edge and pairs each with the other patch's NEAREST edge
// (within 2 mm). Two covers side by side around the limb (a's R 145 edge on b's R 0 edge) that meet along only
// the last 15.5 mm of a (b mounted 134.5 mm further along): a's 90 % point (Y 135) lands 0.5 mm from b's Y 0
// edge and 1 mm from its R 0 edge, so the seam is recorded as a R_max | b Y_min; from b's side, a Y_max | b R_min.
// A seam between an R edge and a Y edge is no seam (perpendicular lines: OntoEdge moves the two contacts onto
// lines that cross), and the real R | R seam is not found.
TEST(Review4SeamFusion, ASeamPairsParallelEdges) {
  std::vector<robot::MountedSurface> surfaces = {{Patch("a", "fore", 0.0, 40.0).mount, 150.0, 145.0},
                                                 {Patch("b", "fore", 0.1345, 40.0, 145.0).mount, 150.0, 145.0}};
  const auto seams = robot::FindSeams(surfaces);
  auto is_y = [](robot::PatchEdge e) { return e == robot::PatchEdge::kYMin || e == robot::PatchEdge::kYMax; };
  for (const auto& s : seams) {
    std::printf("  seam %zu %s | %zu %s\n", s.a, robot::ToString(s.edge_a), s.b, robot::ToString(s.edge_b));
    EXPECT_EQ(is_y(s.edge_a), is_y(s.edge_b)) << robot::ToString(s.edge_a) << " | " << robot::ToString(s.edge_b);
  }
  EXPECT_GE(seams.size(), 1u);
}

// FAILED at 2915829 (passes since the fix). kMaxSeams (64) is below what kMaxPatches (64) patches may have: a forearm tiled 4 around x 9
// along (36 patches, 30 mm long each) has 36 seams around and 32 along. Fuser throws at construction, so the
// aggregator of such a scene no longer starts -- even with safety.seam_sum off (the default), and although the
// scene ran before 2915829. Fail-closed, but a regression the docs do not mention (docs/fusion.md: "at most").
TEST(Review4SeamFusion, AScenesSeamsFitTheCap) {
  FusionConfig c;
  for (int along = 0; along < 9; ++along) {
    for (int around = 0; around < 4; ++around) {
      char name[16];
      std::snprintf(name, sizeof name, "p%d_%d", along, around);
      FusionPatch p = Patch(name, "fore", 0.03 * along, 40.0, 90.0 * around);
      p.extent_y_mm = 30.0;
      p.extent_r_deg = 90.0;
      c.patches.push_back(p);
    }
  }
  std::vector<robot::MountedSurface> surfaces;
  for (const FusionPatch& p : c.patches) surfaces.push_back({p.mount, p.extent_y_mm, p.extent_r_deg});
  for (const robot::Seam& s : robot::FindSeams(surfaces)) c.seams.push_back({s, 10.0, 10.0});
  std::printf("36 patches: %zu seams (cap %zu)\n", c.seams.size(), kMaxSeams);
  const robot::Model model = testing::TestModel();
  EXPECT_NO_THROW(Fuser(model, c));
}

}  // namespace
}  // namespace ruffini::fusion
