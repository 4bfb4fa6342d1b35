#pragma once
// One touch or more (issue 16, docs/decoders.md "Two touches"): is a frame's shift pattern one touch?
//
// The paper's networks know one touch: two touches give one place between them (a phantom) or at one of them,
// with a confident covariance. The check uses the model's ResponseMap (one touch's response, shift_i =
// F (1 + c F) g_i(Y, R), learned from a recording): near the networks' place it finds the single touch that
// best explains the shifts (amplitude in closed form at each node of a small window) and measures the misfit,
// the residual's share of the shifts' energy (with a noise allowance, so a light touch's noise is no misfit).
// Above the model's limit the frame is not one touch: a two-touch fit (each place searched over the whole map
// while the other is held, amplitudes by non-negative least squares) then gives both places and forces, each
// force with its sd (the residual over how strongly the place moves the gratings). The pipeline places the
// contact at the pair's centre of pressure and may raise its force to a touch's lower bound
// (PipelineConfig::multi_force): a place of weak response (far from every grating) explains a few pm with any
// force, so a force counts only where its place is seen well (a light touch's misfit can fit a pair of 10 N).
//
// Cost: the single check is a 5 x 5 node window (about 0.5 us); the two-touch fit, only on frames the check
// flags, a few passes over the map's nodes. No allocation, no lock, no throw.
#include <array>
#include <cstdint>
#include <limits>
#include <vector>

#include "ruffini/decode/inversion.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::decode {

struct Touch {
  double y_mm = 0.0, r_deg = 0.0, force_n = 0.0;
  // The force's 1-sigma from the fit: the residual per grating over how strongly the place moves the
  // gratings (with the other touch's share taken out). A place far from every grating has a large sd.
  double force_sd_n = std::numeric_limits<double>::infinity();
  double gain_pm_per_n = 0.0;  // the place's largest response, max_i |g_i| (pm/N): how strongly it is seen
  int node = -1;  // the map node (internal: Amplitudes re-solves the forces there)
};

struct TouchVerdict {
  double misfit = 0.0;     // the best single touch's misfit near the start (0..1)
  bool multiple = false;   // misfit above the model's limit: not one touch
  int found = 0;           // 2: the two-touch fit explains the shifts (touch[0], touch[1]); 0: it does not
  double misfit_two = 0.0; // the two-touch fit's misfit (with found 2)
  // found 2: the two touches. Otherwise touch[0] is the best single touch near the start (force 0: none).
  std::array<Touch, 2> touch{};
};

class TouchCheck {
 public:
  // Throws InputError when the map is malformed (sizes, steps, non-finite values).
  explicit TouchCheck(const v1::ResponseMap& map);
  // fit_pair false: a frame flagged multiple gets no two-touch fit (found stays 0; the caller reuses a recent
  // one). The fit is the check's costly part (about 100 us).
  // confirm_anywhere: a frame the window flags is one touch after all when the best single touch anywhere on the
  // map (Unexplained, about 10 us, flagged frames only) leaves at most the limit's misfit (review 14 finding 3:
  // a single touch the networks place a few mm off is flagged by the window; measured, off by default).
  // window_nodes: the single check's window, +- that many nodes around (y_mm, r_deg) (2: +-3 mm at the fit's 1.5 mm).
  TouchVerdict Check(const ShiftsPm& shift_pm, double y_mm, double r_deg, bool fit_pair = true,
                     bool confirm_anywhere = false, int window_nodes = kDefaultWindow) const noexcept;
  static constexpr int kDefaultWindow = 2;
  // A found pair's forces (and sds) re-solved on this frame's shifts at the pair's places: the frames between
  // two fits follow the touches' forces (a 2 x 2 least squares, well under a microsecond). A pair that no
  // longer fits with both amplitudes >= 0 keeps found 2 with the force of the touch that went negative 0.
  void Amplitudes(const ShiftsPm& shift_pm, TouchVerdict& pair) const noexcept;
  // The best single touch anywhere on the map (amplitude >= 0: a press pushes), searched every 2 nodes and
  // refined at full resolution: the residual energy it leaves, pm^2 (the shifts' own energy when no place
  // explains any of them). A lone grating moved against the sign every touch gives it leaves its whole
  // energy (docs/decoders.md, "Plausibility of a contact"). About 10 us; no allocation.
  [[nodiscard]] double Unexplained(const ShiftsPm& shift_pm) const noexcept;
  [[nodiscard]] double limit() const noexcept { return limit_; }
  [[nodiscard]] const ResponseModel& model() const noexcept { return model_; }

 private:
  struct Best {
    int node = -1;
    double cost = 0.0, a = 0.0;
  };
  // The single node of [iy0, iy1] x [ir0, ir1] (step `stride`) whose g explains s best (amplitude >= 0).
  Best SearchOne(const ShiftsPm& s, int iy0, int iy1, int ir0, int ir1, int stride) const noexcept;
  // The node (same window) that with the fixed node `other` explains s best; amplitudes >= 0.
  Best SearchPair(const ShiftsPm& s, int other, int iy0, int iy1, int ir0, int ir1, int stride, double& a_other) const noexcept;
  [[nodiscard]] double Force(double amplitude) const noexcept;
  [[nodiscard]] Touch Place(int node, double amplitude) const noexcept;
  // Forces and sds of the pair (p, q) on s: non-negative least squares, the residual as the noise.
  void SolvePair(const ShiftsPm& s, int p, int q, TouchVerdict& v) const noexcept;

  ResponseModel model_;
  double limit_ = 0.0;
};

// The map as a model file stores it, and back (the fit lives in inversion.h).
v1::ResponseMap ToProto(const ResponseModel& m, double multiple_misfit, const std::string& source);
ResponseModel FromProto(const v1::ResponseMap& map);

}  // namespace ruffini::decode
