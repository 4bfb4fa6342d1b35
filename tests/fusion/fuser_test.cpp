// The fuser: seams on one link and across adjacent links, the gate's boundary, non-adjacent links, normals,
// force-only contacts, three contributors, determinism, bad inputs counted, config errors.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <limits>
#include <random>
#include <vector>

#include "fixture.h"
#include "ruffini/error.h"
#include "ruffini/fusion/fuser.h"

namespace ruffini::fusion {
namespace {

using testing::ForceOnly;
using testing::Located;
using testing::Patch;

// Patch index: 0 fore_a (fore z 0..0.15), 1 fore_b (fore 0.15..0.30), 2 hand_a (hand 0..0.15, continues
// fore_b across j3), 3 upper_a (upper 0.15..0.30, continues into fore_a across j2), 4 upper_far (upper
// 0.6..0.75: in space exactly where hand_a is at q = 0, but upper and hand are not adjacent), 5 fore_c
// (fore 0.075..0.225, overlapping fore_a and fore_b). All radius 40 mm, R = 0 on the link's -y side.
FusionConfig Config() {
  FusionConfig c;
  c.patches = {Patch("fore_a", "fore", 0.0),   Patch("fore_b", "fore", 0.15),     Patch("hand_a", "hand", 0.0),
               Patch("upper_a", "upper", 0.15), Patch("upper_far", "upper", 0.6), Patch("fore_c", "fore", 0.075)};
  return c;
}

struct World {
  robot::Model model = testing::TestModel();
  robot::Data fk = testing::PosesAtZero(model);
  Fuser fuser;
  FusionData data;
  explicit World(FusionConfig c = Config()) : fuser(model, std::move(c)) {}
  std::span<const BodyContact> Run(const std::vector<PatchInput>& in) {
    fuser.Update(in, fk.X_BL, data);
    return data.contacts();
  }
  LiftedContact LiftOne(std::size_t patch, const SurfaceContact& c) const {
    LiftedContact out;
    EXPECT_EQ(Lift(fuser.config().patches[patch], fk.X_BL[fuser.patch_link(patch)], c, fuser.config().lift, out),
              Rejection::kNone);
    return out;
  }
};

void ExpectSane(const BodyContact& b) {
  EXPECT_TRUE(b.p_BC_m.allFinite());
  EXPECT_TRUE(b.n_B.allFinite());
  EXPECT_NEAR(b.n_B.norm(), 1.0, 1e-12);
  EXPECT_TRUE(b.cov_p_BC_m2.allFinite());
  EXPECT_EQ(b.cov_p_BC_m2, b.cov_p_BC_m2.transpose());
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(b.cov_p_BC_m2).eigenvalues()[0], 0.0);
  EXPECT_TRUE(std::isfinite(b.force_n) && std::isfinite(b.force_var_n2));
  EXPECT_EQ(static_cast<std::size_t>(__builtin_popcountll(b.patches)), b.num_patches);
}

TEST(Fuser, SeamContactIsOneContactWithTheForcesSummed) {
  World w;
  const auto out = w.Run({{0, Located(148, 60, 1.0)}, {1, Located(2, 60, 1.5)}});
  ASSERT_EQ(out.size(), 1u);
  const BodyContact& b = out[0];
  ExpectSane(b);
  EXPECT_DOUBLE_EQ(b.force_n, 2.5);
  EXPECT_NEAR(b.force_var_n2, 2 * 0.05 * 0.05, 1e-15);
  EXPECT_TRUE(b.HasPatch(0));
  EXPECT_TRUE(b.HasPatch(1));
  EXPECT_EQ(b.num_patches, 2u);
  EXPECT_EQ(b.link, *w.model.FindLink("fore"));
  EXPECT_TRUE(b.located);
  EXPECT_TRUE(b.uncertainty_calibrated);
  // Between the two, on the seam (fore's origin is 0.3 m up; the seam 0.15 m up fore).
  EXPECT_NEAR(b.p_BC_m.z(), 0.45, 1e-4);
  const auto la = w.LiftOne(0, Located(148, 60)), lb = w.LiftOne(1, Located(2, 60));
  EXPECT_LE(b.cov_p_BC_m2.trace(), std::min(la.cov_p_BC_m2.trace(), lb.cov_p_BC_m2.trace()));
  EXPECT_NEAR(b.n_B.dot(la.n_B), 1.0, 1e-12);
  EXPECT_EQ(w.data.counters.merges, 1u);
}

// Seams with bands (docs/fusion.md, "Seams"): fore_a's Y = 150 edge meets fore_b's Y = 0 edge.
FusionConfig WithSeamBands(double band_a_mm, double band_b_mm) {
  FusionConfig c = Config();
  std::vector<robot::MountedSurface> surfaces;
  for (const FusionPatch& p : c.patches) surfaces.push_back({p.mount, p.extent_y_mm, p.extent_r_deg});
  for (const robot::Seam& s : robot::FindSeams(surfaces)) c.seams.push_back({s, band_a_mm, band_b_mm});
  return c;
}

TEST(Fuser, FindSeamsFindsTheSeamOnALinkButNotAnOverlapOrAJoint) {
  const FusionConfig c = WithSeamBands(25, 25);
  ASSERT_EQ(c.seams.size(), 1u);  // fore_c overlaps both fore patches; upper_a and hand_a meet them across joints
  EXPECT_EQ(c.seams[0].seam.a, 0u);
  EXPECT_EQ(c.seams[0].seam.b, 1u);
  EXPECT_EQ(c.seams[0].seam.edge_a, robot::PatchEdge::kYMax);
  EXPECT_EQ(c.seams[0].seam.edge_b, robot::PatchEdge::kYMin);
}

TEST(Fuser, ContactsPulledInFromASeamAreOneContactOnTheSeam) {
  // Each decoder places a touch on the seam 20 mm inside its own patch (as an interior-trained decoder does),
  // with a confident 2 mm sd: 40 mm apart, the plain gate keeps them apart.
  const std::vector<PatchInput> in = {{0, Located(130, 60, 1.0)}, {1, Located(20, 60, 1.5)}};
  World plain;
  EXPECT_EQ(plain.Run(in).size(), 2u);
  World w(WithSeamBands(25, 25));
  const auto out = w.Run(in);
  ASSERT_EQ(out.size(), 1u);
  const BodyContact& b = out[0];
  ExpectSane(b);
  EXPECT_DOUBLE_EQ(b.force_n, 2.5);
  EXPECT_EQ(b.num_patches, 2u);
  EXPECT_EQ(w.data.counters.seam_pairs, 1u);
  // On the seam (fore's origin 0.3 m up, the seam 0.15 m up fore), at the contacts' R.
  EXPECT_NEAR(b.p_BC_m.z(), 0.45, 1e-9);
  const auto seam_point = w.LiftOne(0, Located(150, 60));
  EXPECT_NEAR((b.p_BC_m - seam_point.p_BC_m).norm(), 0.0, 1e-9);
  // Across the seam (along z here) the covariance holds each contact's own place: sd half of (band + 2 own sd),
  // (25 + 4) / 2 = 14.5 mm.
  EXPECT_NEAR(std::sqrt(b.cov_p_BC_m2(2, 2)) * 1e3, 14.5, 0.01);
  // Along it, no more than either contact's own 2 mm.
  const Eigen::Vector3d t_s = (seam_point.n_B.cross(Eigen::Vector3d::UnitZ())).normalized();
  EXPECT_LE(t_s.dot(b.cov_p_BC_m2 * t_s) * 1e6, 4.0 + 1e-6);

  // A contact outside its band is not on the seam: nothing changes.
  EXPECT_EQ(World(WithSeamBands(15, 25)).Run(in).size(), 2u);
  EXPECT_EQ(World(WithSeamBands(25, 15)).Run(in).size(), 2u);
  EXPECT_EQ(World(WithSeamBands(0, 25)).Run(in).size(), 2u);  // a side without a band: no seam rule
  // Apart along the seam (30 deg of arc = 21 mm at 2 mm sd each): not one place, so one contact on the seam
  // whose covariance holds both places (their mixture), forces summed.
  World apart(WithSeamBands(25, 25));
  const auto mixed = apart.Run({{0, Located(130, 50, 1.0)}, {1, Located(20, 80, 1.5)}});
  ASSERT_EQ(mixed.size(), 1u);
  ExpectSane(mixed[0]);
  EXPECT_DOUBLE_EQ(mixed[0].force_n, 2.5);
  EXPECT_EQ(apart.data.counters.seam_mixtures, 1u);
  EXPECT_NEAR(mixed[0].p_BC_m.z(), 0.45, 1e-9);
  for (const double r : {50.0, 80.0}) {
    const Eigen::Vector3d d = w.LiftOne(0, Located(150, r)).p_BC_m - mixed[0].p_BC_m;
    EXPECT_LT(d.dot(mixed[0].cov_p_BC_m2.ldlt().solve(d)), 2.0) << "R " << r << " lies within 1.5 sd";
  }
  // Normals 60 deg apart (R 30 and 90): never one contact, seam or not.
  World far(WithSeamBands(25, 25));
  const auto two = far.Run({{0, Located(130, 30, 1.0)}, {1, Located(20, 90, 1.5)}});
  ASSERT_EQ(two.size(), 2u);
  EXPECT_EQ(far.data.counters.seam_pairs, 0u);
  EXPECT_NEAR(two[0].p_BC_m.z(), 0.43, 1e-9);
  // A force-only side: the plain rules (gated with the covering covariance).
  World one_located(WithSeamBands(25, 25));
  one_located.Run({{0, Located(130, 60, 1.0)}, {1, ForceOnly(1.5)}});
  EXPECT_EQ(one_located.data.counters.seam_pairs, 0u);
}

TEST(Fuser, SeamBandsAreValidated) {
  const robot::Model model = testing::TestModel();
  FusionConfig c = WithSeamBands(25, 25);
  c.seams[0].band_b_mm = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(Fuser(model, c), InputError);
  c = WithSeamBands(25, -1);
  EXPECT_THROW(Fuser(model, c), InputError);
  c = WithSeamBands(25, 25);
  c.seams[0].seam.b = 99;
  try {
    Fuser f(model, c);
    FAIL() << "accepted a seam to patch 99";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("fusion.seams[0]"), std::string::npos) << e.what();
  }
}

TEST(Fuser, GateAcceptsNearAndRejectsFar) {
  // 2 mm sd on both surface axes for each: the difference along Y has variance 8 mm^2, so the gate (5.991)
  // accepts up to sqrt(5.991 x 8) = 6.92 mm apart.
  World w;
  EXPECT_EQ(w.Run({{0, Located(146.0, 30)}, {1, Located(2.5, 30)}}).size(), 1u);  // 6.5 mm
  EXPECT_EQ(w.Run({{0, Located(145.5, 30)}, {1, Located(2.5, 30)}}).size(), 2u);  // 7.0 mm
  EXPECT_EQ(w.Run({{0, Located(20, 30)}, {1, Located(130, 30)}}).size(), 2u);
  const auto out = w.Run({{0, Located(20, 30, 1.0)}, {1, Located(130, 30, 2.0)}});
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].patches, 1u);  // in patch order
  EXPECT_EQ(out[1].patches, 2u);
  EXPECT_DOUBLE_EQ(out[0].force_n, 1.0);
  EXPECT_DOUBLE_EQ(out[1].force_n, 2.0);
  // Around the limb too: 6.5 mm of arc apart across patches at the same Y.
  const double deg_per_mm = 1.0 / (40.0 * testing::kDeg);
  EXPECT_EQ(w.Run({{0, Located(149, 30)}, {5, Located(74, 30 + 6.5 * deg_per_mm)}}).size(), 1u);
  EXPECT_EQ(w.Run({{0, Located(149, 30)}, {5, Located(74, 30 + 7.0 * deg_per_mm)}}).size(), 2u);
}

TEST(Fuser, AdjacentLinksFuseAndOthersNeverDo) {
  World w;
  const std::size_t fore = *w.model.FindLink("fore"), hand = *w.model.FindLink("hand");
  // Across j3: fore_b's wrist edge meets hand_a's elbow edge. The link is the larger force's.
  auto out = w.Run({{1, Located(148, 40, 1.0)}, {2, Located(2, 40, 3.0)}});
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].link, hand);
  out = w.Run({{1, Located(148, 40, 3.0)}, {2, Located(2, 40, 1.0)}});
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].link, fore);
  // Across j2: upper_a into fore_a.
  EXPECT_EQ(w.Run({{3, Located(148, 40)}, {0, Located(2, 40)}}).size(), 1u);
  // upper_far and hand_a see the same point, but upper and hand are not adjacent.
  out = w.Run({{4, Located(10, 40)}, {2, Located(10, 40)}});
  ASSERT_EQ(out.size(), 2u);
  EXPECT_LT((out[0].p_BC_m - out[1].p_BC_m).norm(), 1e-12);
  // ... unless the config says so.
  FusionConfig c = Config();
  c.adjacent_links = {{"hand", "upper"}};
  World w2(c);
  EXPECT_EQ(w2.Run({{4, Located(10, 40)}, {2, Located(10, 40)}}).size(), 1u);
  // Without the model's parent relation, fore and hand are not adjacent either.
  c = Config();
  c.adjacent_from_model = false;
  World w3(c);
  EXPECT_EQ(w3.Run({{1, Located(148, 40)}, {2, Located(2, 40)}}).size(), 2u);
  EXPECT_EQ(w3.Run({{0, Located(148, 40)}, {1, Located(2, 40)}}).size(), 1u);  // same link: always
  EXPECT_TRUE(w3.fuser.Adjacent(fore, fore));
  EXPECT_FALSE(w3.fuser.Adjacent(fore, hand));
  EXPECT_TRUE(w.fuser.Adjacent(hand, fore));
}

TEST(Fuser, NormalsTooFarApartAreNotOneContact) {
  // Wide covariances let the positions pass the gate; normals 60 deg apart do not.
  FusionConfig c = Config();
  World w(c);
  const std::vector<PatchInput> in{{0, Located(148, 0, 1.0, 60.0)}, {1, Located(2, 60, 1.0, 60.0)}};
  EXPECT_EQ(w.Run(in).size(), 2u);
  c.max_normal_angle_deg = 90;
  World w2(c);
  const auto out = w2.Run(in);
  ASSERT_EQ(out.size(), 1u);
  ExpectSane(out[0]);
  // The normal is the renormalised mean: 30 deg from each.
  const auto la = w2.LiftOne(0, in[0].contact), lb = w2.LiftOne(1, in[1].contact);
  EXPECT_NEAR(out[0].n_B.dot(la.n_B), std::cos(30 * testing::kDeg), 1e-12);
  EXPECT_NEAR(out[0].n_B.dot(lb.n_B), std::cos(30 * testing::kDeg), 1e-12);
}

TEST(Fuser, ForceOnlyContacts) {
  World w;
  // A force-only contact on fore_a and a located one just over the seam: one contact, located, the force
  // summed, the normal the located one's, the position about the located one's.
  auto out = w.Run({{0, ForceOnly(0.5)}, {1, Located(2, 72.5, 1.0)}});
  ASSERT_EQ(out.size(), 1u);
  ExpectSane(out[0]);
  EXPECT_TRUE(out[0].located);
  EXPECT_FALSE(out[0].uncertainty_calibrated);
  EXPECT_DOUBLE_EQ(out[0].force_n, 1.5);
  const auto lb = w.LiftOne(1, Located(2, 72.5));
  EXPECT_LT((out[0].p_BC_m - lb.p_BC_m).norm(), 2e-4);
  EXPECT_NEAR(out[0].n_B.dot(lb.n_B), 1.0, 1e-12);
  // Located far from the force-only patch: two contacts.
  EXPECT_EQ(w.Run({{0, ForceOnly(0.5)}, {1, Located(140, 72.5)}}).size(), 2u);
  // Two force-only contacts are never merged.
  out = w.Run({{0, ForceOnly(0.5)}, {5, ForceOnly(0.7)}});
  ASSERT_EQ(out.size(), 2u);
  EXPECT_FALSE(out[0].located);
  EXPECT_FALSE(out[1].located);
  // fuse_unlocated = false: never with anything.
  FusionConfig c = Config();
  c.fuse_unlocated = false;
  World w2(c);
  EXPECT_EQ(w2.Run({{0, ForceOnly(0.5)}, {1, Located(2, 72.5, 1.0)}}).size(), 2u);
}

TEST(Fuser, ThreeContributorsFusePairwiseInPatchOrder) {
  World w;
  const SurfaceContact a = Located(149, 72.5, 1.0, 2.0), b = Located(1, 72.5, 2.0, 3.0), c = Located(74, 73.0, 4.0, 1.5);
  const auto out = w.Run({{5, c}, {1, b}, {0, a}});
  ASSERT_EQ(out.size(), 1u);
  ExpectSane(out[0]);
  EXPECT_EQ(out[0].num_patches, 3u);
  EXPECT_DOUBLE_EQ(out[0].force_n, 7.0);
  EXPECT_EQ(w.data.counters.merges, 2u);
  // CI(CI(a, b), c): patch 0, then 1, then 5.
  const auto la = w.LiftOne(0, a), lb = w.LiftOne(1, b), lc = w.LiftOne(5, c);
  Estimate ab, abc;
  ASSERT_EQ(CovarianceIntersection({la.p_BC_m, la.cov_p_BC_m2}, {lb.p_BC_m, lb.cov_p_BC_m2}, ab), CovarianceStatus::kOk);
  ASSERT_EQ(CovarianceIntersection(ab, {lc.p_BC_m, lc.cov_p_BC_m2}, abc), CovarianceStatus::kOk);
  EXPECT_EQ(out[0].p_BC_m, abc.x);
  EXPECT_EQ(out[0].cov_p_BC_m2, abc.P);
  EXPECT_NEAR(out[0].n_B.dot((la.n_B + lb.n_B + lc.n_B).normalized()), 1.0, 1e-15);
}

bool Same(const BodyContact& a, const BodyContact& b) {
  return a.link == b.link && a.p_BC_m == b.p_BC_m && a.n_B == b.n_B && a.cov_p_BC_m2 == b.cov_p_BC_m2 &&
         a.force_n == b.force_n && a.force_var_n2 == b.force_var_n2 && a.located == b.located &&
         a.uncertainty_calibrated == b.uncertainty_calibrated && a.patches == b.patches && a.num_patches == b.num_patches;
}

TEST(Fuser, DeterministicWhateverTheInputOrder) {
  World w;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> y(0, 150), r(0, 145), f(0, 5), u(0, 1);
  for (int round = 0; round < 200; ++round) {
    std::vector<PatchInput> in;
    for (std::size_t p = 0; p < w.fuser.num_patches(); ++p) {
      if (u(rng) < 0.3) continue;
      // Half the time near the fore seam so that merges happen.
      const double yy = u(rng) < 0.5 ? (p == 0 ? 147 + 3 * u(rng) : p == 1 ? 3 * u(rng) : p == 5 ? 73 + 4 * u(rng) : y(rng)) : y(rng);
      in.push_back({p, u(rng) < 0.15 ? ForceOnly(f(rng)) : Located(yy, u(rng) < 0.5 ? 60 + 4 * u(rng) : r(rng), f(rng), 1 + 3 * u(rng))});
    }
    const auto first = w.Run(in);
    const std::vector<BodyContact> reference(first.begin(), first.end());
    for (int k = 0; k < 5; ++k) {
      std::shuffle(in.begin(), in.end(), rng);
      FusionData fresh;
      w.fuser.Update(in, w.fk.X_BL, fresh);
      const auto again = fresh.contacts();
      ASSERT_EQ(again.size(), reference.size());
      for (std::size_t i = 0; i < again.size(); ++i) EXPECT_TRUE(Same(again[i], reference[i]));
    }
    std::uint64_t all = 0;
    for (const auto& b : reference) {
      ExpectSane(b);
      EXPECT_EQ(all & b.patches, 0u);  // each patch in exactly one contact
      all |= b.patches;
    }
    EXPECT_EQ(static_cast<std::size_t>(__builtin_popcountll(all)), in.size());
  }
  EXPECT_GT(w.data.counters.merges, 50u);
}

TEST(Fuser, BadInputsAreCountedAndNeverReachTheOutput) {
  World w;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  SurfaceContact bad = Located(148, 60);
  bad.force_n = nan;
  SurfaceContact neg = Located(10, 10);
  neg.force_n = -1;
  const std::vector<PatchInput> in{{0, bad}, {99, Located(1, 1)}, {1, Located(2, 60, 1.0)}, {1, Located(3, 60, 9.0)},
                                   {2, Located(50, 50, 2.0)}, {3, neg}};
  const auto out = w.Run(in);
  ASSERT_EQ(out.size(), 2u);
  for (const auto& b : out) ExpectSane(b);
  EXPECT_DOUBLE_EQ(out[0].force_n, 1.0);  // the first of patch 1's two contacts
  const auto& c = w.data.counters;
  EXPECT_EQ(c.inputs, 6u);
  EXPECT_EQ(c.accepted, 2u);
  EXPECT_EQ(c.rejected[static_cast<std::size_t>(Rejection::kNotFinite)], 1u);
  EXPECT_EQ(c.rejected[static_cast<std::size_t>(Rejection::kUnknownPatch)], 1u);
  EXPECT_EQ(c.rejected[static_cast<std::size_t>(Rejection::kDuplicatePatch)], 1u);
  EXPECT_EQ(c.rejected[static_cast<std::size_t>(Rejection::kNegativeForce)], 1u);
  EXPECT_EQ(c.rejected_total(), 4u);
  EXPECT_EQ(w.data.last_rejection, Rejection::kNegativeForce);

  // Poses: too few (hand is link 3) or not finite.
  FusionData d;
  const std::array<Eigen::Isometry3d, 3> short_poses{w.fk.X_BL[0], w.fk.X_BL[1], w.fk.X_BL[2]};
  w.fuser.Update(std::vector<PatchInput>{{2, Located(10, 10)}, {0, Located(10, 10)}}, short_poses, d);
  EXPECT_EQ(d.contacts().size(), 1u);
  EXPECT_EQ(d.counters.rejected[static_cast<std::size_t>(Rejection::kBadPose)], 1u);
  robot::Data broken = w.fk;
  broken.X_BL[2].translation().y() = nan;  // fore
  w.fuser.Update(std::vector<PatchInput>{{2, Located(10, 10)}, {0, Located(10, 10)}, {1, Located(10, 10)}}, broken.X_BL, d);
  EXPECT_EQ(d.contacts().size(), 1u);
  EXPECT_EQ(d.counters.rejected[static_cast<std::size_t>(Rejection::kBadPose)], 3u);
  // An empty update empties the output.
  w.fuser.Update({}, w.fk.X_BL, d);
  EXPECT_TRUE(d.contacts().empty());
}

TEST(Fuser, ConfigErrorsNameTheField) {
  const auto model = testing::TestModel();
  auto expect_error = [&](FusionConfig c, const std::string& message) {
    try {
      Fuser f(model, std::move(c));
      ADD_FAILURE() << "no error, expected: " << message;
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), message);
    }
  };
  FusionConfig c = Config();
  c.patches[3].id = "fore_a";
  expect_error(c, "fusion.patches[3].id ('fore_a') is a duplicate");
  c = Config();
  c.patches.clear();
  expect_error(c, "fusion.patches: 0 patches; expected 1 to 64");
  c = Config();
  c.patches.resize(65, Patch("x", "fore", 0));
  expect_error(c, "fusion.patches: 65 patches; expected 1 to 64");
  c = Config();
  c.gate_chi2 = 0;
  expect_error(c, "fusion.gate_chi2 (0) must lie in (0, 1e6]");
  c = Config();
  c.max_normal_angle_deg = std::numeric_limits<double>::quiet_NaN();
  expect_error(c, "fusion.max_normal_angle_deg (nan) must lie in (0, 180]");
  c = Config();
  c.adjacent_links = {{"fore", "tail"}};
  expect_error(c, "fusion.adjacent_links[0].second: link 'tail' is not in three.urdf");
  c = Config();
  c.patches[1].mount.link = "tail";
  expect_error(c, "fusion.patches[1].mount: link 'tail' is not in three.urdf (links: base_link, upper, fore, hand)");
  c = Config();
  c.lift.min_surface_sd_mm = -1;
  expect_error(c, "fusion.lift.min_surface_sd_mm (-1) must lie in (0, 100]");
  const Fuser ok(model, Config());
  EXPECT_EQ(ok.FindPatch("hand_a"), 2u);
  EXPECT_FALSE(ok.FindPatch("nope"));
  EXPECT_EQ(ok.patch_id(5), "fore_c");
}

}  // namespace
}  // namespace ruffini::fusion
