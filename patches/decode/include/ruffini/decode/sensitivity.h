#pragma once
// Sensitivity maps (ruffini.v1.SensitivityMap, issue 16: "the decoder knows where it is weak") and what a
// region's patches can guarantee with them (docs/coverage.md).
//
// A map, measured for one level L (a region threshold), gives at each grid point p of a patch the smallest
// force F(p) of a ladder from which on presses are reported above L reliably. The aggregator stops on a
// decoded force above the region's threshold T; a map of level L >= T is conservative for T (reported above
// L is reported above T). A region's covered surface is its patches' surface outside the bands the scene accepts
// as uncovered. The map's grid lines cut a patch into cells; every grid corner of a cell that holds covered
// surface is judged. A region guarantees T when every judged F(p) <= press_factor x T (a press that strong
// stops anywhere there) and every covered cell has its corners within reach (kMaxMapEdgeGapMm,
// kMaxMapCellMm). The smallest threshold it can guarantee is max judged F(p) / press_factor.
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "ruffini/v1/model.pb.h"

namespace ruffini::decode {

// Shapes (one value per grid point), ascending grids and ladder, finite positive level, reliability in
// (0, 1], min_force_n > 0 (or +infinity), location errors >= 0 or NaN. Throws InputError naming `where`.
void ValidateSensitivity(const v1::SensitivityMap& map, const std::string& where);

// The map of the smallest level at or above threshold_n, or nullptr when there is none.
const v1::SensitivityMap* MapForThreshold(const google::protobuf::RepeatedPtrField<v1::SensitivityMap>& maps,
                                          double threshold_n);

// How far from one edge of its patch the decoder places a touch that is on that edge (the fusion's seam
// bands, docs/fusion.md "Seams"): over the map's grid points at most near_mm from the edge (distance_mm(y_mm,
// r_deg) gives a point's distance on the surface), the `quantile` of distance + location error, over the
// points whose error is finite. 0 when no such point has one.
double EdgeReachMm(const v1::SensitivityMap& map, const std::function<double(double, double)>& distance_mm,
                   double near_mm = 5.0, double quantile = 0.9);

// A part of a patch a scene accepts as not covered (safety.coverage.accepted_uncovered).
struct UncoveredBand {
  std::string name;
  std::string patch;  // empty: every patch
  double y_min_mm = 0, y_max_mm = 0, r_min_deg = 0, r_max_deg = 0;
  std::string source;
  [[nodiscard]] bool On(const std::string& patch_id) const noexcept { return patch.empty() || patch == patch_id; }
  [[nodiscard]] bool Contains(double y_mm, double r_deg) const noexcept {
    return y_mm >= y_min_mm && y_mm <= y_max_mm && r_deg >= r_min_deg && r_deg <= r_max_deg;
  }
};

// One patch of a region, with its model's maps (none: the model has no map).
struct CoveragePatch {
  std::string id;
  const google::protobuf::RepeatedPtrField<v1::SensitivityMap>* maps = nullptr;
  double extent_y_mm = 150.0, extent_r_deg = 145.0;  // the spec's surface
  double mm_per_deg = 0.0;  // arc length per degree on the surface (the spec's radius); 0: R edges not judged
};

// A map's grid reaches within this of each edge of its patch (`ruffini sensitivity` measures 2 mm from each
// edge); a wider strip between an edge and the map's outermost grid line was never measured.
inline constexpr double kMaxMapEdgeGapMm = 2.5;
// The widest cell between two grid lines (in Y, and in arc along R) whose corners may stand for it: the
// `ruffini sensitivity` grid's 5 mm, the spacing whose cell centres the mid-cell measurement checked
// (docs/coverage.md, "Between the grid points"). A wider cell holding covered surface was never measured.
inline constexpr double kMaxMapCellMm = 5.0 + 1e-6;

struct BandCount {
  std::string name;
  std::uint32_t points = 0, uncovered_points = 0;
};

// A judged grid point that misses the guarantee (reliable force above press_factor x T). It may lie in an accepted
// band: a corner of a covered cell is judged wherever it lies.
struct UncoveredPoint {
  std::string patch;
  double y_mm = 0, r_deg = 0;
  float min_force_n = 0;
};

struct RegionGuarantee {
  double threshold_n = 0, press_factor = 0;
  double map_level_n = std::numeric_limits<double>::quiet_NaN();  // NaN: some patch has no usable map
  double stop_force_n = std::numeric_limits<double>::infinity();   // max reliable force over the covered surface
  double guaranteed_threshold_n = std::numeric_limits<double>::infinity();
  std::uint32_t patches = 0;  // the region's patches
  std::uint32_t points = 0;
  std::uint32_t covered_points = 0;  // judged: the grid corners of the cells that hold covered surface
  std::vector<BandCount> bands;          // the accepted bands on this region's patches, in the scene's order
  std::vector<std::string> unmapped;     // patches whose model has no map at or above the threshold
  std::vector<UncoveredPoint> uncovered; // covered points missing the guarantee (what a band would have to accept)
  // Covered surface the map never measured: an edge strip wider than kMaxMapEdgeGapMm (review 10, finding 4), an
  // inner cell wider than kMaxMapCellMm or a grid beyond its patch (review 11), each holding a point outside the
  // accepted bands. Each makes the guarantee infinite.
  std::vector<std::string> unmeasured;
  // The scene's threshold is guaranteed: no unmapped patch (unless accepted whole) and threshold_n >=
  // guaranteed_threshold_n.
  [[nodiscard]] bool ok() const noexcept {
    return unmapped.empty() && unmeasured.empty() && threshold_n >= guaranteed_threshold_n;
  }
};

// Computes a region's guarantee. A patch with no map at or above threshold_n + judge_margin_n is unmapped
// unless one band accepts all of its extent. map_level_n is the largest level used over the region's patches.
// judge_margin_n: the most the stop rule may lower a force before it is compared with the threshold
// (safety.stop_rule with sd_k < 0: |sd_k| x max_sd_n), so a press must be reported above threshold + margin.
RegionGuarantee GuaranteeRegion(const std::vector<CoveragePatch>& patches, const std::vector<UncoveredBand>& bands,
                                double threshold_n, double press_factor, double judge_margin_n = 0.0);

}  // namespace ruffini::decode
