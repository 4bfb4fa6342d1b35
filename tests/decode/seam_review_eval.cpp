// Review 3 probes of the seam rule through both forearm patches' whole decode paths (seam.h's rigs), printed as
// text. Not a test.
//
//   seam_review_eval SCENE SEED pairs N  fa=LO:HI fb=LO:HI d=LO:HI      two separate touches at once
//   seam_review_eval SCENE SEED probe N  y=LO:HI off=LO:HI              one probe near the seam: coverage
//
// pairs: one touch on each side of the seam (patch a at d mm of arc inside its seam edge, patch b likewise; Y of
// each uniform in 15..135 mm, independent; forces uniform in fa / fb N), each loading only its own patch (draws
// whose footprint reaches the other cover are skipped and counted). Per hold frame (the rigs share one clock):
// STOP on each patch's own force, and with the seam sum as aggregate::Core::JudgeOnSeam judges it
// (fusion::OneTouchOnSeam, on exact frame pairs). And how often the fusion makes them one body contact, and then
// whether each true touch lies in its 95 % region (tangent plane, chi2 2 dof).
// probe: one probe, centre at off mm of arc from the seam (negative: inside patch a), Y uniform in y, force
// log-uniform 2..50 N; per hold frame, the body contact nearest the truth and whether the truth lies in its 95 %
// region (fused frames, one-patch frames), with and without the seam rule; then 40 interior presses on patch a.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "ruffini/fusion/covariance.h"
#include "ruffini/twin/protocols.h"
#include "seam.h"

namespace {

using namespace ruffini;

struct Range {
  double lo = 0, hi = 0;
};

Range ParseRange(const std::string& v) {
  const auto c = v.find(':');
  if (c == std::string::npos) throw std::runtime_error("expected LO:HI, got '" + v + "'");
  return {std::stod(v.substr(0, c)), std::stod(v.substr(c + 1))};
}

double Pct(double a, double b) { return b > 0 ? 100.0 * a / b : 0.0; }

double D2(const fusion::BodyContact& b, const Eigen::Vector3d& truth) {
  return fusion::TangentMahalanobis2({b.p_BC_m, b.cov_p_BC_m2}, {truth, Eigen::Matrix3d::Zero()}, b.n_B);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 5) {
    std::fprintf(stderr, "usage: %s SCENE SEED pairs|probe N [key=LO:HI ...]\n", argv[0]);
    return 2;
  }
  try {
    const twin::Scene scene = twin::LoadScene(argv[1]);
    const std::uint64_t seed = std::stoull(argv[2]);
    const std::string mode = argv[3];
    const int n = std::stoi(argv[4]);
    Range fa{0.5, 0.75}, fb{0.5, 0.75}, d{8, 35}, y{15, 135}, off{-6, 6};
    for (int i = 5; i < argc; ++i) {
      const std::string kv = argv[i];
      const auto eq = kv.find('=');
      const std::string k = kv.substr(0, eq), v = kv.substr(eq + 1);
      if (k == "fa") fa = ParseRange(v);
      else if (k == "fb") fb = ParseRange(v);
      else if (k == "d") d = ParseRange(v);
      else if (k == "y") y = ParseRange(v);
      else if (k == "off") off = ParseRange(v);
      else throw std::runtime_error("unknown knob '" + k + "'");
    }
    const double threshold = 1.5;
    const testing::SeamRig rig(scene, threshold);
    const robot::Seam& seam = rig.seam();
    if (seam.edge_a != robot::PatchEdge::kRMax || seam.edge_b != robot::PatchEdge::kRMin) {
      throw std::runtime_error("expects an R seam: a's r_max | b's r_min");
    }
    const robot::MountedSurface& sa = rig.surface(seam.a);
    const double mm_per_deg = sa.mount.surface_radius_mm * std::numbers::pi / 180.0;
    const fusion::Fuser& fuser = rig.fuser();
    const fusion::FusionConfig& fc = fuser.config();
    fusion::FusionConfig plain_config = fc;
    plain_config.seams.clear();
    const fusion::Fuser plain(rig.mounts().robot.model, plain_config);
    const robot::Data& fk = rig.fk();
    auto truth_of = [&](std::size_t patch, double y_mm, double r_deg) {
      const robot::MountedPatch& mp = rig.mounts().robot.patches[patch];
      return Eigen::Vector3d(fk.X_BL[mp.link_index] * robot::PatchToLink(mp.mount, {y_mm, r_deg}).p_LS_m);
    };
    const twin::ContactLaw* law = rig.rig(0).twin().contact_law(scene.probe);
    auto radius = [&](double f) {
      return law != nullptr ? law->ContactRadiusMm(std::min(f, law->linear_limit_force_n())) : scene.probe.radius_mm;
    };
    std::printf("bands %.1f / %.1f mm; seed %llu; mode %s\n", rig.band_mm(0), rig.band_mm(1),
                static_cast<unsigned long long>(seed), mode.c_str());
    std::mt19937_64 rng(twin::DeriveSeed(seed, 0));
    std::uint64_t k = 0;
    fusion::FusionData data;

    if (mode == "pairs") {
      std::uniform_real_distribution<double> uy(15.0, 135.0), ud(d.lo, d.hi), ufa(fa.lo, fa.hi), ufb(fb.lo, fb.hi);
      int used = 0, skipped = 0, own_stops = 0, sum_stops = 0, merged_pairs = 0, any_frames = 0;
      long both_frames = 0, merged_frames = 0, uncovered_frames = 0, sum_frames = 0;
      for (int i = 0; i < n; ++i) {
        const double ya = uy(rng), yb = uy(rng), da = ud(rng), db = ud(rng), f_a = ufa(rng), f_b = ufb(rng);
        const double ra = sa.extent_r_deg - da / mm_per_deg, rb = db / mm_per_deg;
        const auto la = sim::ProbeLoads(scene, &rig.mounts(), seam.a, ya, ra, radius(f_a));
        const auto lb = sim::ProbeLoads(scene, &rig.mounts(), seam.b, yb, rb, radius(f_b));
        if (la.size() != 1 || lb.size() != 1) {
          ++skipped;
          continue;
        }
        ++used;
        const testing::ProbeAt pa{ya, ra, f_a}, pb{yb, rb, f_b};
        const testing::PressOutcome oa = rig.rig(0).Press(std::span(&pa, 1), threshold, twin::DeriveSeed(seed, ++k));
        const testing::PressOutcome ob = rig.rig(1).Press(std::span(&pb, 1), threshold, twin::DeriveSeed(seed, ++k));
        const Eigen::Vector3d ta = truth_of(seam.a, ya, ra), tb = truth_of(seam.b, yb, rb);
        bool own_stop = oa.stop_force || ob.stop_force, sum_stop = own_stop, merged_any = false;
        long merged_here = 0, both_here = 0;
        for (std::size_t x = 0; x < oa.hold.size(); ++x) {
          const auto it = std::find(ob.hold_t_ns.begin(), ob.hold_t_ns.end(), oa.hold_t_ns[x]);
          if (it == ob.hold_t_ns.end()) continue;
          const link::Contact& cb = ob.hold[static_cast<std::size_t>(it - ob.hold_t_ns.begin())];
          const fusion::SurfaceContact a = testing::SeamRig::Surface(oa.hold[x]), b = testing::SeamRig::Surface(cb);
          ++both_here;
          const bool on = testing::SeamSumApplies(fc, fc.seams[0], a, b);
          if (on && a.force_n + b.force_n > threshold && std::max(a.force_n, b.force_n) <= threshold) {
            sum_stop = true;
            ++sum_frames;
          }
          const std::vector<fusion::PatchInput> in{{seam.a, a}, {seam.b, b}};
          fuser.Update(in, fk.X_BL, data);
          for (const fusion::BodyContact& bc : data.contacts()) {
            if (bc.num_patches != 2) continue;
            ++merged_here;
            if (D2(bc, ta) > fusion::kChi2_2dof_95 || D2(bc, tb) > fusion::kChi2_2dof_95) ++uncovered_frames;
          }
        }
        any_frames += both_here > 0;
        both_frames += both_here;
        merged_frames += merged_here;
        merged_any = 2 * merged_here > both_here && both_here > 0;
        merged_pairs += merged_any;
        own_stops += own_stop;
        sum_stops += sum_stop;
        if (std::getenv("SEAM_VERBOSE")) {
          std::fprintf(stderr, "A Y %.0f d %.1f %.2f N (max %.2f) | B Y %.0f d %.1f %.2f N (max %.2f): both %ld merged %ld %s%s\n",
                       ya, da, f_a, oa.max_force_n, yb, db, f_b, ob.max_force_n, both_here, merged_here,
                       own_stop ? "OWN-STOP " : "", sum_stop && !own_stop ? "SUM-STOP" : "");
        }
      }
      std::printf("pairs: forces a %.2f..%.2f N, b %.2f..%.2f N, %.0f..%.0f mm from the seam each, Y independent 15..135\n",
                  fa.lo, fa.hi, fb.lo, fb.hi, d.lo, d.hi);
      std::printf("%d pairs (%d skipped: footprint on both covers); %d with hold frames where both report\n", used, skipped,
                  any_frames);
      std::printf("STOP on a patch's own force: %d (%.1f %%)\n", own_stops, Pct(own_stops, used));
      std::printf("STOP with the seam sum:      %d (%.1f %%)  (+%d false STOPs from the sum; %ld frames)\n", sum_stops,
                  Pct(sum_stops, used), sum_stops - own_stops, sum_frames);
      std::printf("fused into one body contact: %d pairs (%.1f %%); %ld of %ld frames with both; of those frames %ld (%.1f %%) "
                  "leave a true touch outside the contact's 95 %% region\n",
                  merged_pairs, Pct(merged_pairs, used), merged_frames, both_frames, uncovered_frames,
                  Pct(static_cast<double>(uncovered_frames), static_cast<double>(merged_frames)));
      return 0;
    }

    if (mode == "probe") {
      std::uniform_real_distribution<double> uy(y.lo, y.hi), uoff(off.lo, off.hi), ulog(std::log(2.0), std::log(50.0));
      struct Tally {
        long frames = 0, covered = 0;
        std::vector<double> err;
      };
      Tally fused, single, plain_t, interior;
      int used = 0;
      auto nearest = [&](const fusion::FusionData& fd, const Eigen::Vector3d& t) -> const fusion::BodyContact* {
        const fusion::BodyContact* best = nullptr;
        double e = 1e9;
        for (const fusion::BodyContact& bc : fd.contacts()) {
          if (!bc.located) continue;
          const double x = (bc.p_BC_m - t).norm();
          if (x < e) {
            e = x;
            best = &bc;
          }
        }
        return best;
      };
      fusion::FusionData pdata;
      for (int i = 0; i < n; ++i) {
        const double yy = uy(rng), o = uoff(rng), f = std::exp(ulog(rng));
        const double r = sa.extent_r_deg + o / mm_per_deg;  // on a's cylinder, may pass its edge
        const auto loads = sim::ProbeLoads(scene, &rig.mounts(), seam.a, yy, r, radius(f));
        const sim::PatchLoad* on[2] = {nullptr, nullptr};
        for (const sim::PatchLoad& l : loads) {
          if (l.patch == seam.a) on[0] = &l;
          if (l.patch == seam.b) on[1] = &l;
        }
        if (on[0] == nullptr && on[1] == nullptr) continue;
        ++used;
        testing::PressOutcome out[2];
        for (int s = 0; s < 2; ++s) {
          if (on[s] == nullptr) continue;
          const testing::ProbeAt p{on[s]->y_mm, on[s]->r_deg, f * on[s]->share};
          out[s] = rig.rig(s).Press(std::span(&p, 1), threshold, twin::DeriveSeed(seed, ++k));
        }
        // The truth: on a's cylinder at (yy, r), or on b's when r passes a's edge (the same point in space).
        const Eigen::Vector3d t = truth_of(seam.a, yy, r);
        std::vector<std::int64_t> times = out[0].hold_t_ns;
        times.insert(times.end(), out[1].hold_t_ns.begin(), out[1].hold_t_ns.end());
        std::sort(times.begin(), times.end());
        times.erase(std::unique(times.begin(), times.end()), times.end());
        for (const std::int64_t tt : times) {
          std::vector<fusion::PatchInput> in;
          for (int s = 0; s < 2; ++s) {
            const auto it = std::find(out[s].hold_t_ns.begin(), out[s].hold_t_ns.end(), tt);
            if (it == out[s].hold_t_ns.end()) continue;
            in.push_back({s == 0 ? seam.a : seam.b,
                          testing::SeamRig::Surface(out[s].hold[static_cast<std::size_t>(it - out[s].hold_t_ns.begin())])});
          }
          fuser.Update(in, fk.X_BL, data);
          if (const fusion::BodyContact* bc = nearest(data, t)) {
            Tally& tl = bc->num_patches == 2 ? fused : single;
            ++tl.frames;
            tl.covered += D2(*bc, t) <= fusion::kChi2_2dof_95;
            tl.err.push_back((bc->p_BC_m - t).norm() * 1e3);
          }
          plain.Update(in, fk.X_BL, pdata);
          if (const fusion::BodyContact* bc = nearest(pdata, t)) {
            ++plain_t.frames;
            plain_t.covered += D2(*bc, t) <= fusion::kChi2_2dof_95;
            plain_t.err.push_back((bc->p_BC_m - t).norm() * 1e3);
          }
        }
      }
      std::uniform_real_distribution<double> iy(30.0, 120.0), ir(40.0, 105.0);
      for (int i = 0; i < 40; ++i) {
        const double yy = iy(rng), r = ir(rng), f = std::exp(ulog(rng));
        const testing::ProbeAt p{yy, r, f};
        const testing::PressOutcome o = rig.rig(0).Press(std::span(&p, 1), threshold, twin::DeriveSeed(seed, ++k));
        const Eigen::Vector3d t = truth_of(seam.a, yy, r);
        for (const link::Contact& c : o.hold) {
          const std::vector<fusion::PatchInput> in{{seam.a, testing::SeamRig::Surface(c)}};
          fuser.Update(in, fk.X_BL, data);
          if (const fusion::BodyContact* bc = nearest(data, t)) {
            ++interior.frames;
            interior.covered += D2(*bc, t) <= fusion::kChi2_2dof_95;
            interior.err.push_back((bc->p_BC_m - t).norm() * 1e3);
          }
        }
      }
      auto med = [](std::vector<double> v) {
        if (v.empty()) return std::nan("");
        std::sort(v.begin(), v.end());
        return v[v.size() / 2];
      };
      std::printf("probe: Y %.0f..%.0f mm, centre %.1f..%.1f mm from the seam (+: into b), 2..50 N; %d probes\n", y.lo, y.hi,
                  off.lo, off.hi, used);
      auto row = [&](const char* what, const Tally& t) {
        std::printf("  %-44s %6ld frames, truth inside the 95 %% region %5.1f %%, error median %.1f mm\n", what, t.frames,
                    Pct(static_cast<double>(t.covered), static_cast<double>(t.frames)), med(t.err));
      };
      row("seam rule, nearest contact fused (2 patches)", fused);
      row("seam rule, nearest contact one patch", single);
      row("plain gate, nearest contact", plain_t);
      row("interior presses on a (reference)", interior);
      return 0;
    }
    throw std::runtime_error("mode is pairs or probe");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "seam_review_eval: %s\n", e.what());
    return 1;
  }
}
