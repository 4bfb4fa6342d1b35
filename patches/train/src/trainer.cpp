#include "ruffini/train/trainer.h"

#include "ruffini/decode/baseline.h"

#include <ATen/CPUGeneratorImpl.h>
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <thread>
#include <atomic>
#include <exception>
#include <numbers>
#include <optional>
#include <numeric>
#include <random>

#include "ruffini/decode/grids.h"
#include "ruffini/error.h"
#include "ruffini/patch/geometry.h"
#include "ruffini/stats.h"
#include "export.h"
#include "nets.h"

namespace ruffini::train {
namespace {

using namespace detail;  // the nets (nets.h) and their export (export.h)

// Modules initialise from the global generator: build them one at a time, reseeded, so a fit's initial
// weights depend on its seed only, whichever thread builds it when.
std::mutex& InitMutex() {
  static std::mutex m;
  return m;
}

using Frame16 = std::array<float, kG>;

// What a location net sees of one frame before z-scoring (NaN where a grating is missing). With `unit`, the
// shifts divided by their norm over the present gratings (at least `floor_pm`), as the runtime does.
Frame16 LocationInputOf(const eval::Prepared& p, std::size_t frame, bool unit, float floor_pm) {
  Frame16 v = p.shift_pm[frame];
  if (!unit) return v;
  double n2 = 0;
  for (float x : v) {
    if (std::isfinite(x)) n2 += static_cast<double>(x) * x;
  }
  const float scale = 1.0f / std::max(static_cast<float>(std::sqrt(n2)), floor_pm);
  for (float& x : v) x *= scale;  // NaN stays NaN
  return v;
}

// z-scored value, missing values at z = 0 (the runtime does the same).
float Z(float v, const Norm& norm, int i) {
  const auto u = static_cast<std::size_t>(i);
  return std::isfinite(v) ? (v - norm.mean[u]) / norm.std[u] : 0.0f;
}

template <typename Get>  // Get: frame -> Frame16
Norm ComputeNorm(const std::vector<std::uint32_t>& frames, Get&& get) {
  Norm n;
  std::array<double, kG> s{}, s2{};
  std::array<std::size_t, kG> c{};
  for (auto f : frames) {
    const Frame16 v = get(f);
    for (std::size_t i = 0; i < kG; ++i) {
      if (!std::isfinite(v[i])) continue;
      s[i] += v[i];
      s2[i] += static_cast<double>(v[i]) * v[i];
      ++c[i];
    }
  }
  for (std::size_t i = 0; i < kG; ++i) {
    const double cnt = static_cast<double>(c[i]);
    const double mean = c[i] ? s[i] / cnt : 0.0;
    const double var = c[i] ? std::max(0.0, s2[i] / cnt - mean * mean) : 1.0;
    n.mean[i] = static_cast<float>(mean);
    // A channel that never moves (a dead grating, or one far from every contact) must not divide by ~0.
    n.std[i] = static_cast<float>(std::max(std::sqrt(var), 1e-3));
  }
  return n;
}

struct Pools {
  std::vector<std::uint32_t> frames;   // force-net samples
  std::vector<std::uint32_t> gated;    // location samples (force label above the gate)
};

Pools MakePools(const eval::Prepared& p, const std::vector<std::size_t>& indentations, double gate_n) {
  Pools pools;
  for (std::size_t i : indentations) {
    for (std::size_t f = p.ranges[i].first; f < p.ranges[i].second; ++f) {
      const auto& s = p.shift_pm[f];
      if (!std::isfinite(p.force_n[f]) || std::all_of(s.begin(), s.end(), [](float v) { return !std::isfinite(v); })) continue;
      pools.frames.push_back(static_cast<std::uint32_t>(f));
      if (p.force_n[f] > gate_n && std::isfinite(p.y_mm[f]) && std::isfinite(p.r_deg[f])) {
        pools.gated.push_back(static_cast<std::uint32_t>(f));
      }
    }
  }
  return pools;
}

// Deterministic subsample of at most n entries.
std::vector<std::uint32_t> Subsample(const std::vector<std::uint32_t>& v, std::size_t n) {
  if (v.size() <= n) return v;
  std::vector<std::uint32_t> out;
  const double step = static_cast<double>(v.size()) / static_cast<double>(n);
  for (std::size_t k = 0; k < n; ++k) out.push_back(v[static_cast<std::size_t>(static_cast<double>(k) * step)]);
  return out;
}

class Trainer {
 public:
  Trainer(const eval::Prepared& p, const patch::PatchSpec& spec, const TrainOptions& o, const TrainProgress& progress)
      : p_(p), spec_(spec), o_(o), progress_(progress), grids_(o.area == "whole" ? decode::WholeSurfaceGrids(spec) : decode::PaperGrids(spec.indented_area)) {
    start_of_.resize(p.size(), 0);
    for (const auto& r : p.ranges) {
      for (std::size_t f = r.first; f < r.second; ++f) start_of_[f] = static_cast<std::uint32_t>(r.first);
    }
  }

  using Nets = FitNets;

  Nets Fit(const Pools& pools, const std::string& phase) {
    Nets n;
    n.force_norm = ComputeNorm(pools.frames, [&](std::uint32_t f) { return p_.shift_pm[f]; });
    n.loc_norm = ComputeNorm(pools.gated, [&](std::uint32_t f) { return LocRaw(f); });
    double s = 0, s2 = 0;
    for (auto f : pools.frames) {
      s += p_.force_n[f];
      s2 += static_cast<double>(p_.force_n[f]) * p_.force_n[f];
    }
    const double cnt = static_cast<double>(std::max<std::size_t>(1, pools.frames.size()));
    n.f_mean = static_cast<float>(s / cnt);
    n.f_std = static_cast<float>(std::max(1e-3, std::sqrt(std::max(0.0, s2 / cnt - (s / cnt) * (s / cnt)))));

    {
      const std::lock_guard lock(InitMutex());
      torch::manual_seed(o_.seed);
      n.force = ForceNet(o_.window);
    }
    std::mt19937_64 rng(o_.seed * 7919 + 1);
    TrainLoop(*n.force, pools.frames, o_.epochs_force, o_.lr_force, phase + " force", rng, [&](const auto& batch) {
      const auto out = n.force->forward(ForceInput(batch, n.force_norm, &rng));
      const auto target = ForceTarget(batch, n);
      return o_.force_loss == "l1" ? torch::l1_loss(out, target) : torch::mse_loss(out, target);
    });
    std::vector<int> classes;
    for (const auto& g : grids_) classes.push_back(g.classes());
    n.mlps = MlpBank(o_.mlp_widths, classes, o_.dropout, at::make_generator<at::CPUGeneratorImpl>(o_.seed + 101));
    TrainLoop(*n.mlps, pools.gated, o_.epochs_location, o_.lr_location, phase + " location (4 grids)", rng,
              [&](const auto& batch) {
                const auto logp = torch::log_softmax(n.mlps->forward(LocInput(batch, n.loc_norm, &rng)), 2);
                // Cross-entropy per grid (mean over the batch), summed over the grids.
                return -(LocTargets(batch, logp.size(2)) * logp).sum(2).mean(1).sum();
              });
    return n;
  }

  // Median/IQR absolute errors: force in mN over `frames`; location in mm (per grid and union) over `gated`.
  std::vector<stats::Summary> Errors(Nets& n, const Pools& pools) {
    torch::NoGradGuard no_grad;
    n.force->eval();
    std::vector<stats::Summary> out;
    const auto frames = Subsample(pools.frames, 60000);
    std::vector<double> err;
    for (std::size_t k = 0; k < frames.size(); k += 4096) {
      const std::vector<std::uint32_t> batch(frames.begin() + static_cast<std::ptrdiff_t>(k),
                                             frames.begin() + static_cast<std::ptrdiff_t>(std::min(frames.size(), k + 4096)));
      const auto y = n.force->forward(ForceInput(batch, n.force_norm)).squeeze(1) * n.f_std + n.f_mean;
      const auto acc = y.accessor<float, 1>();
      for (std::size_t j = 0; j < batch.size(); ++j) err.push_back(std::abs(acc[static_cast<long>(j)] - p_.force_n[batch[j]]) * 1e3);
    }
    out.push_back(stats::Summarize(err));
    n.force->train();
    const auto gated = Subsample(pools.gated, 30000);
    const auto probs = LocProbabilities(n, gated);
    const patch::Geometry geo(spec_.surface_radius_mm);
    std::size_t offset = 0;
    std::vector<std::vector<double>> per(grids_.size() + 1);
    std::vector<decode::Nip> single;
    for (const auto& g : grids_) single.emplace_back(std::span<const decode::GridSpec>(&g, 1));
    const decode::Nip all(grids_);
    for (std::size_t g = 0; g <= grids_.size(); ++g) {
      for (std::size_t j = 0; j < gated.size(); ++j) {
        const float* pj = probs.data() + j * all.inputs();
        double y = 0, r = 0;
        if (g < grids_.size()) {
          single[g].Locate(std::span<const float>(pj + offset, static_cast<std::size_t>(grids_[g].classes())), y, r);
        } else {
          all.Locate(std::span<const float>(pj, all.inputs()), y, r);
        }
        per[g].push_back(geo.SurfaceDistanceMm({y, r}, {p_.y_mm[gated[j]], p_.r_deg[gated[j]]}));
      }
      if (g < grids_.size()) offset += static_cast<std::size_t>(grids_[g].classes());
    }
    for (auto& v : per) out.push_back(stats::Summarize(v));
    return out;
  }

  std::vector<float> LocProbabilities(Nets& n, const std::vector<std::uint32_t>& frames) {
    torch::NoGradGuard no_grad;
    std::size_t width = 0;
    for (const auto& g : grids_) width += static_cast<std::size_t>(g.classes());
    std::vector<float> out(frames.size() * width);
    n.mlps->eval();
    const auto logits = n.mlps->forward(LocInput(frames, n.loc_norm));
    n.mlps->train();
    std::size_t offset = 0;
    for (std::size_t g = 0; g < grids_.size(); ++g) {
      const auto c = static_cast<std::size_t>(grids_[g].classes());
      const auto pr = torch::softmax(logits[static_cast<long>(g)].narrow(1, 0, static_cast<long>(c)), 1).contiguous();
      const float* d = pr.data_ptr<float>();
      for (std::size_t j = 0; j < frames.size(); ++j) std::copy(d + j * c, d + (j + 1) * c, out.begin() + static_cast<std::ptrdiff_t>(j * width + offset));
      offset += c;
    }
    return out;
  }

  // The nets into the model file (export.cpp), with golden vectors: libtorch's outputs for a few held-out
  // frames in contact.
  void Export(Nets& n, const Pools& test_pools, v1::DecoderModel& m) {
    ExportNets(n, grids_, o_, m);
    std::vector<std::uint32_t> picks;
    for (auto f : test_pools.gated) {
      if (p_.force_n[f] > 0.3f) picks.push_back(f);
    }
    picks = Subsample(picks, static_cast<std::size_t>(o_.golden_vectors));
    torch::NoGradGuard no_grad;
    n.force->eval();
    const auto probs = LocProbabilities(n, picks);
    const decode::Nip all(grids_);
    std::vector<float> window;
    for (std::size_t j = 0; j < picks.size(); ++j) {
      const std::uint32_t f = picks[j];
      window.clear();
      for (int t = 0; t < o_.window; ++t) {
        const auto back = static_cast<std::size_t>(o_.window - 1 - t);
        const std::size_t src = f >= start_of_[f] + back ? f - back : start_of_[f];  // as ForceInput does
        for (int i = 0; i < kG; ++i) {
          const float v = p_.shift_pm[src][static_cast<std::size_t>(i)];
          window.push_back(std::isfinite(v) ? v : n.force_norm.mean[static_cast<std::size_t>(i)]);
        }
      }
      const auto y = n.force->forward(ForceInput({f}, n.force_norm)).item<float>() * n.f_std + n.f_mean;
      AddGoldenVector(window, y, std::span<const float>(probs.data() + j * all.inputs(), all.inputs()), all, m);
    }
    n.force->train();
  }

  const std::array<decode::GridSpec, 4>& grids() const { return grids_; }

 private:
  template <typename LossFn>
  void TrainLoop(torch::nn::Module& net, const std::vector<std::uint32_t>& pool, int epochs, double lr,
                 const std::string& phase, std::mt19937_64& rng, LossFn&& loss_fn) {
    if (pool.empty()) throw InputError("training: no samples for " + phase + " (is the dataset labelled?)");
    std::unique_ptr<torch::optim::Optimizer> opt;
    const double base_lr = o_.optimizer == "adam" ? lr * 0.1 : lr;
    if (o_.optimizer == "adam") {
      opt = std::make_unique<torch::optim::Adam>(net.parameters(), torch::optim::AdamOptions(base_lr));
    } else {
      opt = std::make_unique<torch::optim::SGD>(net.parameters(), torch::optim::SGDOptions(lr).momentum(o_.momentum));
    }
    net.train();
    std::uniform_int_distribution<std::size_t> pick(0, pool.size() - 1);
    const int steps = std::max(1, o_.frames_per_epoch / o_.batch);
    std::vector<std::uint32_t> batch(static_cast<std::size_t>(o_.batch));
    for (int e = 0; e < epochs; ++e) {
      if (o_.lr_schedule == "cosine") {
        // Cosine decay over the epochs, from the base rate down to 2 % of it in the last epoch.
        const double t = epochs > 1 ? static_cast<double>(e) / (epochs - 1) : 1.0;
        const double rate = base_lr * (0.02 + 0.98 * 0.5 * (1.0 + std::cos(std::numbers::pi * t)));
        for (auto& group : opt->param_groups()) group.options().set_lr(rate);
      }
      double total = 0;
      for (int s = 0; s < steps; ++s) {
        for (auto& b : batch) b = pool[pick(rng)];
        opt->zero_grad();
        torch::Tensor loss = loss_fn(batch);
        loss.backward();
        opt->step();
        total += loss.item<double>();
      }
      if (progress_) progress_(phase, e + 1, epochs, total / steps);
    }
  }

  // Drift augmentation (training steps only, when drift_augment_pm > 0): one per-grating offset vector per
  // sample, N(0, sigma) with its median removed (the shifts are common-mode free), added to every frame of
  // the sample. It stands for what a frozen baseline accumulates in the field (the per-grating spread of a
  // temperature drift, residual strain), so the nets cannot lean on directions the lab data never move in.
  Frame16 DriftOffset(std::mt19937_64* rng) const {
    Frame16 b{};
    if (rng == nullptr || !(o_.drift_augment_pm > 0)) return b;
    std::normal_distribution<float> normal(0.0f, static_cast<float>(o_.drift_augment_pm));
    decode::ShiftsPm v;
    for (auto& x : v) x = normal(*rng);
    const float med = decode::MedianOfPresent(v, 1);
    for (std::size_t i = 0; i < static_cast<std::size_t>(kG); ++i) b[i] = v[i] - med;
    return b;
  }
  torch::Tensor ForceInput(const std::vector<std::uint32_t>& frames, const Norm& norm, std::mt19937_64* rng = nullptr) const {
    auto x = torch::empty({static_cast<long>(frames.size()), o_.window, kG});
    float* d = x.data_ptr<float>();
    for (std::size_t s = 0; s < frames.size(); ++s) {
      const std::size_t f = frames[s], a = start_of_[f];
      const Frame16 b = DriftOffset(rng);
      for (int t = 0; t < o_.window; ++t) {
        const long back = o_.window - 1 - t;
        const std::size_t src = f >= a + static_cast<std::size_t>(back) ? f - static_cast<std::size_t>(back) : a;
        for (int i = 0; i < kG; ++i) {
          *d++ = Z(p_.shift_pm[src][static_cast<std::size_t>(i)] + b[static_cast<std::size_t>(i)], norm, i);
        }
      }
    }
    return x;
  }
  torch::Tensor ForceTarget(const std::vector<std::uint32_t>& frames, const Nets& n) const {
    auto y = torch::empty({static_cast<long>(frames.size()), 1});
    float* d = y.data_ptr<float>();
    for (auto f : frames) *d++ = (p_.force_n[f] - n.f_mean) / n.f_std;
    return y;
  }
  torch::Tensor LocInput(const std::vector<std::uint32_t>& frames, const Norm& norm, std::mt19937_64* rng = nullptr) const {
    auto x = torch::empty({static_cast<long>(frames.size()), kG});
    float* d = x.data_ptr<float>();
    const bool raw = o_.location_input != "unit";  // unit patterns are not augmented (the offset would be rescaled)
    for (auto f : frames) {
      const Frame16 v = LocRaw(f);
      const Frame16 b = raw ? DriftOffset(rng) : Frame16{};
      for (int i = 0; i < kG; ++i) *d++ = Z(v[static_cast<std::size_t>(i)] + b[static_cast<std::size_t>(i)], norm, i);
    }
    return x;
  }
  Frame16 LocRaw(std::size_t f) const {
    return LocationInputOf(p_, f, o_.location_input == "unit", static_cast<float>(o_.unit_floor_pm));
  }
  // Every grid's target distribution, [grids, N, widest] (zero beyond a grid's cells): one-hot on the
  // contact's cell (the paper's), or soft labels.
  torch::Tensor LocTargets(const std::vector<std::uint32_t>& frames, long widest) const {
    auto y = torch::zeros({static_cast<long>(grids_.size()), static_cast<long>(frames.size()), widest});
    for (std::size_t g = 0; g < grids_.size(); ++g) {
      const auto& grid = grids_[g];
      auto yg = y[static_cast<long>(g)];  // a view; it must outlive the accessor
      if (o_.label_sigma_mm > 0) {
        // Soft labels: a classifier trained on each cell's share of a Gaussian around the contact spreads its
        // probability the same way, so the NIP barycentre can land between fine-cell centres.
        float* d = yg.data_ptr<float>();
        for (std::size_t j = 0; j < frames.size(); ++j) {
          grid.SoftLabels(p_.y_mm[frames[j]], p_.r_deg[frames[j]], o_.label_sigma_mm, spec_.surface_radius_mm,
                          std::span<float>(d + static_cast<long>(j) * widest, static_cast<std::size_t>(grid.classes())));
        }
        continue;
      }
      auto a = yg.accessor<float, 2>();
      for (std::size_t j = 0; j < frames.size(); ++j) {
        a[static_cast<long>(j)][std::max(0, grid.ClassOf(p_.y_mm[frames[j]], p_.r_deg[frames[j]]))] = 1.0f;
      }
    }
    return y;
  }

  const eval::Prepared& p_;
  const patch::PatchSpec& spec_;
  TrainOptions o_;
  TrainProgress progress_;
  std::array<decode::GridSpec, 4> grids_;
  std::vector<std::uint32_t> start_of_;
};

}  // namespace

v1::DecoderModel Train(const eval::Prepared& data, const patch::PatchSpec& spec, const TrainOptions& o,
                       const std::string& dataset_path, const TrainProgress& progress) {
  if (o.window < 1 || o.window > 256) throw InputError("train: window must be 1..256");
  if (o.lr_schedule != "constant" && o.lr_schedule != "cosine") {
    throw InputError("train: learning-rate schedule must be constant or cosine, not '" + o.lr_schedule + "'");
  }
  if (o.force_loss != "mse" && o.force_loss != "l1") {
    throw InputError("train: force loss must be mse or l1, not '" + o.force_loss + "'");
  }
  if (o.location_input != "raw" && o.location_input != "unit") {
    throw InputError("train: location input must be raw or unit, not '" + o.location_input + "'");
  }
  if (o.area != "indented" && o.area != "whole") {
    throw InputError("train: area must be indented or whole, not '" + o.area + "'");
  }
  if (!(o.label_sigma_mm >= 0 && o.label_sigma_mm <= 100)) throw InputError("train: label sigma must be 0..100 mm");
  if (!(o.drift_augment_pm >= 0 && o.drift_augment_pm <= 100)) throw InputError("train: drift augmentation must be 0..100 pm");
  if (!(o.unit_floor_pm > 0)) throw InputError("train: unit floor must be > 0 pm");
  if (o.mlp_widths.size() != 3) throw InputError("train: the location MLPs have exactly 3 hidden layers");
  if (data.ids.size() < 10) throw InputError("train: the dataset has " + std::to_string(data.ids.size()) + " indentations; need at least 10");
  const auto t0 = std::chrono::steady_clock::now();
  // One framework thread per fit: these nets are too small to gain from intra-op threads (measured: a fit
  // is faster on one thread than on two), so the cores run whole fits (CV folds, the final fit) in parallel.
  torch::set_num_threads(1);
  const eval::Split split = eval::MakeSplit(data, o.test_fraction, o.folds, o.seed);
  const int jobs = o.folds + 1;  // job 0: the final fit; job f + 1: fold f
  const int total_epochs = jobs * (o.epochs_force + o.epochs_location);
  std::mutex progress_mutex;
  int epochs_done = 0;
  const TrainProgress serial = [&](const std::string& phase, int, int, double loss) {
    const std::lock_guard lock(progress_mutex);
    ++epochs_done;
    if (progress) progress(phase, epochs_done, total_epochs, loss);
  };
  Trainer trainer(data, spec, o, serial);
  v1::DecoderModel m;
  m.set_format_version(1);
  m.set_patch_name(spec.name);
  m.set_patch_fingerprint(spec.Fingerprint());
  m.set_surface_radius_mm(spec.surface_radius_mm);
  auto* info = m.mutable_training();
  const Pools all_train = MakePools(data, split.train, o.gate_n), test = MakePools(data, split.test, o.gate_n);
  std::vector<std::vector<stats::Summary>> fold_train(static_cast<std::size_t>(o.folds)), fold_val(fold_train.size());
  std::optional<Trainer::Nets> final_nets;
  std::vector<std::exception_ptr> errors(static_cast<std::size_t>(jobs));
  std::atomic<int> next{0};
  auto worker = [&]() {
    for (int j = next++; j < jobs; j = next++) {
      try {
        if (j == 0) {
          final_nets = trainer.Fit(all_train, "final");
          continue;
        }
        const int f = j - 1;
        std::vector<std::size_t> tr, va;
        for (std::size_t k = 0; k < split.train.size(); ++k) (split.fold[k] == f ? va : tr).push_back(split.train[k]);
        const Pools ptr = MakePools(data, tr, o.gate_n), pva = MakePools(data, va, o.gate_n);
        auto nets = trainer.Fit(ptr, "fold " + std::to_string(f + 1) + "/" + std::to_string(o.folds));
        fold_train[static_cast<std::size_t>(f)] = trainer.Errors(nets, ptr);
        fold_val[static_cast<std::size_t>(f)] = trainer.Errors(nets, pva);
      } catch (...) {
        errors[static_cast<std::size_t>(j)] = std::current_exception();
      }
    }
  };
  {
    std::vector<std::jthread> pool;
    for (int t = 1; t < std::min(o.threads, jobs); ++t) pool.emplace_back(worker);
    worker();
  }  // joined
  for (const auto& e : errors) {
    if (e) std::rethrow_exception(e);
  }
  const char* names[6] = {"force", "SG", "VSG", "HSG", "DSG", "union"};
  for (int f = 0; f < o.folds; ++f) {
    const auto& etr = fold_train[static_cast<std::size_t>(f)];
    const auto& eva = fold_val[static_cast<std::size_t>(f)];
    for (std::size_t k = 0; k < 6; ++k) {
      auto* row = info->add_folds();
      row->set_fold(static_cast<std::uint32_t>(f + 1));
      row->set_net(names[k]);
      row->set_train_median(etr[k].median);
      row->set_train_iqr(etr[k].iqr());
      row->set_validation_median(eva[k].median);
      row->set_validation_iqr(eva[k].iqr());
    }
  }
  auto& nets = *final_nets;
  trainer.Export(nets, test, m);
  for (std::size_t i : split.test) m.add_test_indentations(static_cast<std::uint32_t>(data.ids[i]));
  info->set_dataset(dataset_path);
  info->set_dataset_source(data.source);
  info->set_seed(o.seed);
  info->set_optimizer(o.optimizer == "adam" ? "adam" : "sgd momentum " + std::to_string(o.momentum).substr(0, 4));
  info->set_epochs(static_cast<std::uint32_t>(o.epochs_force));
  info->set_epochs_location(static_cast<std::uint32_t>(o.epochs_location));
  info->set_parallel_fits(static_cast<std::uint32_t>(std::min(o.threads, jobs)));
  info->set_train_frames(all_train.frames.size());
  info->set_test_frames(test.frames.size());
  for (int w : o.mlp_widths) info->add_mlp_widths(static_cast<std::uint32_t>(w));
  info->set_dropout(static_cast<float>(o.dropout));
  info->set_frames_per_epoch(static_cast<std::uint32_t>(o.frames_per_epoch));
  info->set_batch(static_cast<std::uint32_t>(o.batch));
  info->set_learning_rate_force(static_cast<float>(o.lr_force));
  info->set_learning_rate_location(static_cast<float>(o.lr_location));
  info->set_force_loss(o.force_loss);
  info->set_lr_schedule(o.lr_schedule);
  info->set_location_label_sigma_mm(static_cast<float>(o.label_sigma_mm));
  info->set_drift_augment_pm(static_cast<float>(o.drift_augment_pm));
  info->set_tool_version("ruffini 0.1.0, libtorch " TORCH_VERSION);
  info->set_seconds(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  return m;
}

}  // namespace ruffini::train
