#pragma once
// The paper's decoding pipeline on Eigen: CNN force net (window of W frames), gated localisation by four
// grid MLPs fused by the multigrid NIP. No libtorch.
//
// Model (immutable, built once from a DecoderModel) and Data (per stream, sized once) are separate; Decode()
// takes both. Convolutions with 'same' padding over the fixed 16-grating axis are linear maps, so each is
// unrolled at load into one dense (Toeplitz) matrix: a layer is then a single matrix-vector product.
#include <Eigen/Core>
#include <array>
#include <memory>
#include <vector>

#include "ruffini/decode/baseline.h"
#include "ruffini/decode/grids.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::decode {

struct DecodeOutput {
  float force_n = 0.0f;
  float y_mm = 0.0f, r_deg = 0.0f;      // valid when located
  float location_sigma_mm = 0.0f;       // spread of the fused cell weights around the estimate
  // Raw (uncalibrated) 2x2 covariance of the estimate on the surface: y and arc length, mm^2.
  float cov_yy_mm2 = 0.0f, cov_ya_mm2 = 0.0f, cov_aa_mm2 = 0.0f;
  float confidence = 0.0f;              // largest fused cell weight / grids, 0..1
  bool in_contact = false;              // the force gate (with hysteresis) is open
  bool located = false;                 // y/r computed this frame
  bool valid = false;                   // false: too many peaks missing (or not enough history); force 0
  std::uint8_t missing = 0;             // gratings whose peak was missing (replaced by their training mean)
};

struct DecoderOptions {
  // Which location nets to fuse (indices into the model's location nets); empty = all (the paper's union).
  std::vector<int> grids;
  int max_missing = 3;  // more missing peaks than this: the frame is invalid
  double sample_rate_hz = 100.0;  // the stream's rate (the model's creep compensation is in seconds)
};

template <typename Scalar>
class NetworkDecoder {
 public:
  using Vector = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;
  using Matrix = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

  // Throws InputError if the model is malformed (call ValidateModel first for a file-named message).
  explicit NetworkDecoder(const v1::DecoderModel& model, DecoderOptions options = {});

  // Per-stream state: the window of recent frames, the gate, the activations.
  class Data {
   public:
    explicit Data(const NetworkDecoder& d);

   private:
    friend class NetworkDecoder;
    Eigen::Matrix<Scalar, Eigen::Dynamic, static_cast<int>(kGratings), Eigen::RowMajor> window;  // ring, W x 16 (z-scored)
    int head = 0, filled = 0;
    bool gate = false;
    std::vector<Vector> act;   // activations per force layer
    Vector flat;               // the window in time order, flattened
    std::vector<Vector> loc;   // activations per location layer (all nets, reused)
    std::vector<float> probabilities;
    std::array<double, 4> creep_x{};  // creep compensation state (applied force, low-passed per term)
  };

  // Real-time safe: no allocation, no lock, no throw.
  DecodeOutput Decode(const ShiftsPm& shift_pm, Data& data) const noexcept;
  // Forgets the stream (window, gate); optionally fills the window with one frame, as if it had been
  // there for W frames (evaluation starts each indentation this way, as training did). Real-time safe.
  void Reset(Data& data, const ShiftsPm* fill = nullptr) const noexcept;
  // The force net alone on an explicit window (oldest first, W x 16 shifts), for golden vectors and tests.
  float ForceOnWindow(const float* window_shift_pm, Data& data) const noexcept;
  // Location probabilities (all selected nets, concatenated) for one frame of shifts.
  void Probabilities(const ShiftsPm& shift_pm, Data& data, std::vector<float>& out) const;

  [[nodiscard]] int window() const noexcept { return window_; }
  [[nodiscard]] const Nip& nip() const noexcept { return *nip_; }
  [[nodiscard]] std::size_t location_inputs() const noexcept { return nip_->inputs(); }

 private:
  struct Layer {
    Matrix w;
    Vector b;
    bool relu = true;
    int channels = 0, length = 0, pool = 1;  // output geometry before pooling (conv layers)
  };
  struct Mlp {
    std::array<Scalar, kGratings> mean{}, inv_std{};
    std::vector<Layer> layers;
    bool unit = false;       // input divided by the shifts' norm (LocationNet.UNIT)
    Scalar unit_floor = 1;   // pm
  };
  void RunForce(Data& d) const noexcept;
  void RunLocation(const std::array<Scalar, kGratings>& raw, const std::array<bool, kGratings>& present, Data& d) const noexcept;

  int window_ = 1;
  std::array<Scalar, kGratings> f_mean_{}, f_inv_std_{};
  std::vector<Layer> force_;
  Scalar out_scale_ = 1, out_offset_ = 0;
  std::vector<Mlp> location_;
  std::unique_ptr<Nip> nip_;
  float gate_on_n_ = 0.05f, gate_off_n_ = 0.04f;
  double radius_mm_ = 37.4;
  int max_missing_ = 3;
  // Creep compensation (model.creep): F = (F_strain - sum g_k (1 - a_k) x_k) / (1 + sum g_k a_k), then
  // x_k += a_k (F - x_k), with a_k = 1 - exp(-dt / tau_k): the exact inverse of the twin's discretised filter.
  int creep_terms_ = 0;
  std::array<double, 4> creep_g_{}, creep_a_{};
};

extern template class NetworkDecoder<float>;
extern template class NetworkDecoder<double>;

}  // namespace ruffini::decode
