#pragma once
// Beyond the paper: a physics-informed decoder that inverts a per-grating response model.
//
// Response model (learned from the same training data as the networks): shift_i = F (1 + c F) g_i(Y, R),
// with g_i a sensitivity map (pm/N) on a regular grid over the indented area, bilinear between nodes, and
// c one global stiffening coefficient. Decoding fits (Y, R, F) to the 16 shifts by least squares: a coarse
// grid search (F in closed form at each node) picks the start, then Levenberg-Marquardt (Eigen's) refines
// it for a fixed number of iterations. The fit's Jacobian gives a covariance (sigma of Y and R in mm), and
// its reduced chi-square says whether the shifts fit a single contact at all: two touches, or a grating
// that lies, give a large chi-square and a low confidence. Missing peaks are left out of the fit.
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "ruffini/decode/baseline.h"
#include "ruffini/decode/network_decoder.h"
#include "ruffini/patch/spec.h"

namespace ruffini::decode {

struct ResponseModel {
  double y0_mm = 0, r0_deg = 0, dy_mm = 2, dr_deg = 2;
  int ny = 0, nr = 0;
  std::vector<std::array<float, kGratings>> g;  // ny * nr nodes, pm per newton
  double stiffening = 0.0;               // c in F (1 + c F)
  double noise_pm = 0.3;                 // per-grating noise assumed by chi-square and covariance
  double surface_radius_mm = 37.4;

  // Fits the model to frames (shifts, force labels, positions) above min_force_n. Nodes without data take
  // their neighbours' values. The grid (1.5 mm steps from the area's near corner) may end up to a step past the
  // area's far edge, never past `within` (the patch; nullptr: no limit). Throws InputError when there are no
  // usable frames.
  static ResponseModel Fit(const std::vector<ShiftsPm>& shift_pm, const std::vector<float>& force_n,
                           const std::vector<float>& y_mm, const std::vector<float>& r_deg,
                           const patch::Region& area, double surface_radius_mm, double min_force_n = 0.1,
                           const patch::Region* within = nullptr);
  // g and its derivatives d/dY, d/dR at a point (clamped to the grid). No allocation.
  void Eval(double y_mm, double r_deg, std::array<double, kGratings>& out, std::array<double, kGratings>* dg_dy = nullptr,
            std::array<double, kGratings>* dg_dr = nullptr) const noexcept;
};

struct InversionOptions {
  int iterations = 10;      // Levenberg-Marquardt iterations after the grid search (0 = grid search only)
  int search_stride = 3;    // coarse search over every n-th node
  double detect_pm = 3.0;   // below this on every grating: no contact, force 0
  int max_missing = 6;
};

class InversionDecoder {
 public:
  InversionDecoder(ResponseModel model, InversionOptions options = {});
  // No lock, no throw; NOT allocation-free: Eigen's LevenbergMarquardt sizes its work vectors per call
  // (its latency, allocation included, is what `ruffini bench` reports).
  DecodeOutput Decode(const ShiftsPm& shift_pm) const noexcept;
  // The last fit's reduced chi-square (for tests and reports).
  struct Fit {
    double y_mm, r_deg, force_n, chi2_reduced, sigma_y_mm, sigma_r_mm;
  };
  Fit Solve(const ShiftsPm& shift_pm, int& used) const noexcept;
  [[nodiscard]] const ResponseModel& model() const noexcept { return model_; }

 private:
  ResponseModel model_;
  InversionOptions options_;
  std::vector<int> search_nodes_;
};

}  // namespace ruffini::decode
