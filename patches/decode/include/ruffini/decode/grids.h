#pragma once
// The paper's localisation grids and the multigrid Neuron Integration Process (NIP).
//
// SG: the indented area cut into 6 (Y) x 5 (R) cells of 20 mm x 18 deg = 30 classes. VSG, HSG, DSG: the same
// grid shifted by half a cell in Y (7 x 5 = 35), in R (6 x 6 = 36) or both (7 x 6 = 42); their outer cells
// stick out half a cell beyond the area. NIP: every cell is split into 2 x 2 fine cells (10 mm x 9 deg);
// overlaid, the four grids share one fine grid (14 x 12 over the extended area). A fine cell's weight is the
// sum of the probabilities of its parent cell in each grid; the contact is the weighted barycentre of the
// fine-cell centres.
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "ruffini/patch/spec.h"

namespace ruffini::decode {

struct GridSpec {
  std::string name;
  double y0_mm = 0, r0_deg = 0;       // corner of cell 0
  double cell_y_mm = 20, cell_r_deg = 18;
  int ny = 0, nr = 0;                 // class k = cell (k / nr, k % nr)
  [[nodiscard]] int classes() const { return ny * nr; }
  // Class of a point, or -1 outside the grid.
  [[nodiscard]] int ClassOf(double y_mm, double r_deg) const;
  [[nodiscard]] patch::SurfacePoint Centre(int k) const;
  // Soft label of a contact: each cell's share of an isotropic Gaussian of sigma_mm on the surface (R
  // converted to arc length on radius_mm), renormalised over the grid; one-hot on the nearest cell when the
  // Gaussian misses the grid. `out` has classes() entries.
  void SoftLabels(double y_mm, double r_deg, double sigma_mm, double radius_mm, std::span<float> out) const;
};

// The four grids over a patch's indented area, in the paper's order SG, VSG, HSG, DSG.
std::array<GridSpec, 4> PaperGrids(const patch::Region& indented_area);
// The paper's four grids over an area cut into ny x nr cells (PaperGrids is 6 x 5 over the indented area).
std::array<GridSpec, 4> PaperGrids(const patch::Region& area, int ny, int nr);
// The four grids over the patch's whole extent (Y 0..extent, R 0..extent; issue 16), with cells as close as
// possible to the paper's (the indented area's sixth in Y, fifth in R): for the paper's patch 8 x 8 cells of
// 18.75 mm x 18.125 deg, so SG 64, VSG 72, HSG 72, DSG 81 classes. The shifted grids stick out half a cell
// beyond the patch, as the paper's stick out beyond its area.
std::array<GridSpec, 4> WholeSurfaceGrids(const patch::PatchSpec& spec);

// Precomputed NIP: fine cells, their centres and their parent class in each grid (-1 = none).
class Nip {
 public:
  explicit Nip(std::span<const GridSpec> grids);
  static constexpr std::size_t kMaxFineCells = 1024;
  struct Estimate {
    double y_mm = 0, r_deg = 0;
    double confidence = 0;  // largest fine-cell weight / grids, 0..1
    double spread_mm = 0;   // weighted RMS distance of the fine cells from the estimate, on the surface
    // Weighted covariance of the fine-cell centres about the estimate, on the surface (y, and arc length a
    // = R in radians x surface radius), mm^2. Uncalibrated: the pipeline scales it (model Uncertainty).
    double cov_yy_mm2 = 0, cov_ya_mm2 = 0, cov_aa_mm2 = 0;
    bool ok = false;        // false when every weight is 0 (nothing to locate)
  };
  // probabilities: each grid's softmax, concatenated in grid order. One pass fuses the weights; a second
  // takes the spread. Real-time safe.
  Estimate Fuse(std::span<const float> probabilities, double surface_radius_mm) const noexcept;
  // The barycentre alone (writes y, r when any weight is positive); returns the confidence.
  double Locate(std::span<const float> probabilities, double& y_mm, double& r_deg) const noexcept;
  [[nodiscard]] std::size_t fine_cells() const { return centre_y_.size(); }
  [[nodiscard]] std::size_t inputs() const { return inputs_; }

 private:
  std::vector<double> centre_y_, centre_r_;
  std::vector<std::int32_t> parent_;  // fine_cells x grids, index into the probabilities; `inputs_` = none
  // Weights of every fine cell (no parent counts as probability 0).
  void Weights(std::span<const float> p, float* w) const noexcept;
  std::size_t grids_ = 0, inputs_ = 0;
  std::vector<std::size_t> none_;  // construction scratch
};

}  // namespace ruffini::decode
