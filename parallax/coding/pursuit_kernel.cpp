// Fused Gram-form matching pursuit on the CPU: the paper's eq. 1 (§3.3), plain MP with k steps,
// and the two sparse products around it (the residuals and the dictionary gradient Bᵀ·R); and
// two one-call compositions of them with ATen operations, which keep the GIL released from start
// to end: a scale's whole encoding (encode_pairs) and its dictionary step with the next Gram
// matrix (dictionary_step).
//
// parallax/coding/native.py builds this file on first use (torch.utils.cpp_extension.load);
// parallax/coding/pursuit.py, dictionary.py and scale.py call it in place of the numpy/torch
// code of reference.py.
//
// gram_pursuit: patch by patch, a row of correlations c = Φ·γ (N values, a few KiB, in L1 cache
// for all the steps):
//
//     repeat k times:  j = argmax_n |c_n|     (first maximum on ties, a NaN counts as the
//                                              maximum: numpy's argmax)
//                      record j and b = c_j
//                      c ← c − b·G[j]          (G = Φ·Φᵀ, so c stays the residual's correlations)
//
// One pass over c does each step's update and the next step's argmax.
//
// The update rounds exactly like torch's addcmul_(b, G[j], value=-1) on this CPU: a fused
// multiply-add when torch's kernels use them (PARALLAX_FMA, set by native.py for its AVX2 and
// AVX512 kernels), a multiply then a subtraction otherwise (built with -ffp-contract=off so the
// compiler does not fuse it by itself). The picks and coefficients are then bit-identical to
// those of the torch path.
//
// codes_and_residuals and codes_times_residuals replace scatter_add_ and torch's embedding_bag
// (reference.py's codes_and_residuals and codes_times_residuals) and add up in the same order
// with the same rounding, so they too are bit-identical. native.py checks every function against
// the numpy/torch code once before the coder uses them.
//
// The coder's helper thread lives here too (a thread of this module's own that never runs
// Python): encode_scales encodes the first scale on the caller's thread while it encodes the
// others, and start_dictionary_steps hands it the dictionary steps of every scale, which the
// caller collects later; neither the hand-offs nor the helper's work take the GIL.

// The few ATen headers it needs rather than <torch/extension.h>, which would make every build
// compile most of torch's headers.
#include <ATen/Dispatch.h>
#include <ATen/Parallel.h>
#include <ATen/core/Tensor.h>
#include <ATen/core/grad_mode.h>
#include <ATen/ops/cat.h>
#include <ATen/ops/empty.h>
#include <ATen/ops/linalg_vector_norm.h>
#include <ATen/ops/matmul.h>
#include <ATen/ops/ones_like.h>
#include <ATen/ops/stack.h>
#include <ATen/ops/where.h>
#include <ATen/ops/zeros.h>
#include <ATen/ops/zeros_like.h>
#include <torch/csrc/utils/pybind.h>

#ifdef PARALLAX_FMA
#include <immintrin.h>
#endif

#include <pthread.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstring>
#include <deque>
#include <functional>
#include <future>
#include <limits>
#include <memory>
#include <mutex>
#include <thread>
#include <tuple>
#include <type_traits>
#include <vector>

namespace {

template <typename T>
inline T subtract_scaled(T value, T coefficient, T gram) {
#ifdef PARALLAX_FMA
  return std::fma(-coefficient, gram, value);
#else
  return value - coefficient * gram;
#endif
}

// acc + w·x the way torch's embedding_bag adds weighted rows: float32 goes through FBGEMM, whose
// kernels use fused multiply-adds; other dtypes through a plain loop that multiplies then adds.
template <typename T>
inline T add_weighted(T acc, T weight, T value) {
  return acc + weight * value;
}
template <>
inline float add_weighted<float>(float acc, float weight, float value) {
  return std::fma(weight, value, acc);
}

// 32-byte vectors (GCC/Clang vector extensions: AVX2 registers when built with -mavx2, pairs of
// SSE registers otherwise), and integer lanes of the same width for indices and masks.
template <typename T> struct Simd;
template <> struct Simd<float> {
  typedef float Values __attribute__((vector_size(32)));
  typedef int32_t Indices __attribute__((vector_size(32)));
};
template <> struct Simd<double> {
  typedef double Values __attribute__((vector_size(32)));
  typedef int64_t Indices __attribute__((vector_size(32)));
};

// v − b·g on a vector, rounded as subtract_scaled rounds each element.
template <typename T>
inline typename Simd<T>::Values subtract_scaled(typename Simd<T>::Values value, T coefficient,
                                                typename Simd<T>::Values gram) {
#ifdef PARALLAX_FMA
  if constexpr (std::is_same_v<T, float>) {
    return (typename Simd<T>::Values)_mm256_fnmadd_ps(_mm256_set1_ps(coefficient), (__m256)gram,
                                                       (__m256)value);
  } else {
    return (typename Simd<T>::Values)_mm256_fnmadd_pd(_mm256_set1_pd(coefficient), (__m256d)gram,
                                                       (__m256d)value);
  }
#else
  return value - coefficient * gram;
#endif
}

// Whether any lane of a comparison's mask is set.
template <typename Mask>
inline bool any_lane(Mask mask) {
  bool any = false;
  for (int l = 0; l < int(sizeof(Mask) / sizeof(mask[0])); ++l) any |= mask[l] != 0;
  return any;
}

// With kUpdate, first c ← c − b·G[j] over the n values (rounded as subtract_scaled); then the
// index of the first maximum of |c|, or of the first NaN if there is one: numpy's argmax of |c|.
// One pass does both, so that c is read once per step. Each lane of kChains independent vectors
// keeps the first of its own maxima (strict >), so that one vector's comparisons need not wait
// for the previous vector's; the lanes are then merged without branches, the larger maximum or
// of equal ones the smaller index winning, over the chains and then the halves of the vector.
template <bool kUpdate, typename T>
int64_t update_and_abs_argmax(T* c, const T* g, T coefficient, int64_t n) {
  using Values = typename Simd<T>::Values;
  using Indices = typename Simd<T>::Indices;
  using Lane = typename std::remove_reference<decltype(Indices{}[0])>::type;
  constexpr int W = sizeof(Values) / sizeof(T);
  constexpr int kChains = 2;
  constexpr int64_t kBlock = int64_t(kChains) * W;
  const Indices magnitude_bits = Indices{} + std::numeric_limits<Lane>::max();  // all but the sign
  Values lane_max[kChains];
  Indices lane_index[kChains];
  Indices lane_nan = {}, lanes = {};
  for (int l = 0; l < W; ++l) lanes[l] = l;
  for (int u = 0; u < kChains; ++u) {
    lane_max[u] = Values{} - 1;   // below any |c|
    lane_index[u] = Indices{};
  }
  auto visit = [&](int64_t j, int u) {
    Values v;
    std::memcpy(&v, c + j, sizeof v);
    if constexpr (kUpdate) {
      Values gram;
      std::memcpy(&gram, g + j, sizeof gram);
      v = subtract_scaled<T>(v, coefficient, gram);
      std::memcpy(c + j, &v, sizeof v);
    }
    const Values magnitude = (Values)((Indices)v & magnitude_bits);
    const Indices larger = magnitude > lane_max[u];
    lane_max[u] = larger ? magnitude : lane_max[u];
    lane_index[u] = larger ? lanes + Lane(j) : lane_index[u];
    lane_nan |= magnitude != magnitude;   // a NaN is never larger: it is looked for apart
  };
  const int64_t blocks = n - n % kBlock;
  int64_t j = 0;
  for (; j < blocks; j += kBlock) {
    for (int u = 0; u < kChains; ++u) visit(j + u * W, u);
  }
  const int64_t whole = n - n % W;
  for (; j < whole; j += W) visit(j, 0);   // chain 0's lanes have seen only smaller indices
  Values top = lane_max[0];
  Indices at = lane_index[0];
  auto merge = [&](Values other, Indices other_at) {
    const Indices take = (other > top) | ((other == top) & (other_at < at));
    top = take ? other : top;
    at = take ? other_at : at;
  };
  for (int u = 1; u < kChains; ++u) merge(lane_max[u], lane_index[u]);
  for (int half = W / 2; half >= 1; half /= 2) {
    Values other;
    Indices other_at;
    for (int l = 0; l < W; ++l) {   // a lane permutation; the compiler makes it a shuffle
      other[l] = top[l ^ half];
      other_at[l] = at[l ^ half];
    }
    merge(other, other_at);
  }
  T best = top[0];
  int64_t best_index = at[0];
  bool any_nan = any_lane(lane_nan);
  for (int64_t k = whole; k < n; ++k) {   // the tail comes after every lane's index
    if constexpr (kUpdate) c[k] = subtract_scaled(c[k], coefficient, g[k]);
    const T magnitude = std::abs(c[k]);
    any_nan |= std::isnan(magnitude);
    if (magnitude > best) {
      best = magnitude;
      best_index = k;
    }
  }
  if (any_nan) {
    for (int64_t k = 0; k < n; ++k) {
      if (std::isnan(c[k])) return k;
    }
  }
  return best_index;
}

template <typename T>
void pursue_rows(T* correlations, const T* gram, int64_t n_atoms, int64_t sparsity,
                 int64_t* picks, T* coefficients, int64_t begin, int64_t end) {
  for (int64_t row = begin; row < end; ++row) {
    T* c = correlations + row * n_atoms;
    int64_t pick = update_and_abs_argmax<false, T>(c, nullptr, T(0), n_atoms);
    for (int64_t step = 0; step < sparsity; ++step) {
      const T coefficient = c[pick];
      picks[row * sparsity + step] = pick;
      coefficients[row * sparsity + step] = coefficient;
      const T* g = gram + pick * n_atoms;
      if (step + 1 < sparsity) {   // the update and the next step's pick in one pass
        pick = update_and_abs_argmax<true, T>(c, g, coefficient, n_atoms);
      } else {
        for (int64_t j = 0; j < n_atoms; ++j) {
          c[j] = subtract_scaled(c[j], coefficient, g[j]);
        }
      }
    }
  }
}

void check_cpu_contiguous(const at::Tensor& tensor, const char* name) {
  TORCH_CHECK(tensor.device().is_cpu() && tensor.is_contiguous(), name,
              " must be a contiguous CPU tensor");
}

void check_picks(const at::Tensor& picks, const at::Tensor& coefficients, int64_t rows,
                 int64_t n_atoms) {
  check_cpu_contiguous(picks, "picks");
  check_cpu_contiguous(coefficients, "coefficients");
  TORCH_CHECK(picks.scalar_type() == at::kLong && picks.dim() == 2 && picks.size(0) == rows &&
                  coefficients.sizes() == picks.sizes(),
              "picks must be (M, k) int64 and coefficients (M, k)");
  const int64_t* p = picks.data_ptr<int64_t>();
  for (int64_t i = 0; i < picks.numel(); ++i) {
    TORCH_CHECK(p[i] >= 0 && p[i] < n_atoms, "pick ", p[i], " is not one of the ", n_atoms, " atoms");
  }
}

// (M, N) correlations, updated in place, and the (N, N) Gram matrix → (M, k) int64 picks and
// (M, k) coefficients.
std::vector<at::Tensor> gram_pursuit(at::Tensor correlations, const at::Tensor& gram,
                                     int64_t sparsity) {
  check_cpu_contiguous(correlations, "correlations");
  check_cpu_contiguous(gram, "gram");
  TORCH_CHECK(correlations.dim() == 2 && gram.dim() == 2 && gram.size(0) == gram.size(1) &&
                  gram.size(0) == correlations.size(1),
              "correlations must be (M, N) and gram (N, N)");
  TORCH_CHECK(correlations.scalar_type() == gram.scalar_type(),
              "correlations and gram must share a dtype");
  TORCH_CHECK(sparsity >= 1, "sparsity must be positive");
  TORCH_CHECK(correlations.size(1) >= 1, "the dictionary needs at least one atom");
  const int64_t rows = correlations.size(0);
  const int64_t n_atoms = correlations.size(1);
  at::Tensor picks = at::empty({rows, sparsity}, correlations.options().dtype(at::kLong));
  at::Tensor coefficients = at::empty({rows, sparsity}, correlations.options());
  AT_DISPATCH_FLOATING_TYPES(correlations.scalar_type(), "gram_pursuit", [&] {
    scalar_t* c = correlations.data_ptr<scalar_t>();
    const scalar_t* g = gram.data_ptr<scalar_t>();
    int64_t* p = picks.data_ptr<int64_t>();
    scalar_t* b = coefficients.data_ptr<scalar_t>();
    at::parallel_for(0, rows, 64, [&](int64_t begin, int64_t end) {
      pursue_rows<scalar_t>(c, g, n_atoms, sparsity, p, b, begin, end);
    });
  });
  return {picks, coefficients};
}

// (M, K) patches, the (N, K) dictionary and the (M, k) picks → the (M, K) residuals
// γ_i − Σ_s c_s·φ_{k_s} and, with ``with_codes``, the (M, N) codes b_{i,n} (repeated picks add up,
// in step order; else an undefined tensor).
std::vector<at::Tensor> reconstruct(const at::Tensor& patches, const at::Tensor& dictionary,
                                    const at::Tensor& picks, const at::Tensor& coefficients,
                                    bool with_codes) {
  check_cpu_contiguous(patches, "patches");
  check_cpu_contiguous(dictionary, "dictionary");
  TORCH_CHECK(patches.dim() == 2 && dictionary.dim() == 2 && patches.size(1) == dictionary.size(1),
              "patches must be (M, K) and dictionary (N, K)");
  TORCH_CHECK(patches.scalar_type() == dictionary.scalar_type() &&
                  coefficients.scalar_type() == patches.scalar_type(),
              "patches, dictionary and coefficients must share a dtype");
  const int64_t rows = patches.size(0), dim = patches.size(1), n_atoms = dictionary.size(0);
  check_picks(picks, coefficients, rows, n_atoms);
  const int64_t sparsity = picks.size(1);
  at::Tensor codes = with_codes ? at::zeros({rows, n_atoms}, patches.options()) : at::Tensor();
  at::Tensor residuals = at::empty({rows, dim}, patches.options());
  AT_DISPATCH_FLOATING_TYPES(patches.scalar_type(), "reconstruct", [&] {
    const scalar_t* x = patches.data_ptr<scalar_t>();
    const scalar_t* phi = dictionary.data_ptr<scalar_t>();
    const int64_t* p = picks.data_ptr<int64_t>();
    const scalar_t* w = coefficients.data_ptr<scalar_t>();
    scalar_t* b = with_codes ? codes.data_ptr<scalar_t>() : nullptr;
    scalar_t* r = residuals.data_ptr<scalar_t>();
    at::parallel_for(0, rows, 64, [&](int64_t begin, int64_t end) {
      std::vector<scalar_t> reconstruction(dim);
      for (int64_t row = begin; row < end; ++row) {
        std::fill(reconstruction.begin(), reconstruction.end(), scalar_t(0));
        for (int64_t step = 0; step < sparsity; ++step) {
          const int64_t atom = p[row * sparsity + step];
          const scalar_t weight = w[row * sparsity + step];
          if (b != nullptr) b[row * n_atoms + atom] += weight;
          const scalar_t* a = phi + atom * dim;
          for (int64_t j = 0; j < dim; ++j) {
            reconstruction[j] = add_weighted(reconstruction[j], weight, a[j]);
          }
        }
        for (int64_t j = 0; j < dim; ++j) {
          r[row * dim + j] = x[row * dim + j] - reconstruction[j];
        }
      }
    });
  });
  return {codes, residuals};
}

// The (M, N) codes and the (M, K) residuals (see reconstruct).
std::vector<at::Tensor> codes_and_residuals(const at::Tensor& patches, const at::Tensor& dictionary,
                                            const at::Tensor& picks,
                                            const at::Tensor& coefficients) {
  return reconstruct(patches, dictionary, picks, coefficients, true);
}

// The (M, K) residuals alone, as codes_and_residuals computes them.
at::Tensor residuals_only(const at::Tensor& patches, const at::Tensor& dictionary,
                          const at::Tensor& picks, const at::Tensor& coefficients) {
  return reconstruct(patches, dictionary, picks, coefficients, false)[1];
}

// θ (eqs. 2–3), (B, N): for each of B images of P patches, mean_i b_{i,n}² with b the dense
// codes (repeated picks added up in step order, as codes_and_residuals does), without making
// the (M, N) codes. The squares are summed over the patches as torch sums a non-innermost
// dimension (aten/src/ATen/native/cpu/SumKernel.cpp, multi_row_sum: four levels of partial
// sums, the first flushed into the next every 2^level_power patches), where the zero terms of
// the dense codes change nothing; then divided by P. native.py checks it against
// codes.square().mean(dim=1) and does not use it if they differ.
at::Tensor pooled_activity(const at::Tensor& picks, const at::Tensor& coefficients,
                           int64_t patches, int64_t n_atoms) {
  TORCH_CHECK(patches >= 1 && n_atoms >= 1, "patches and n_atoms must be positive");
  TORCH_CHECK(picks.dim() == 2 && picks.size(0) % patches == 0,
              "picks must be (B·P, k) for P = ", patches);
  check_picks(picks, coefficients, picks.size(0), n_atoms);
  const int64_t images = picks.size(0) / patches, sparsity = picks.size(1);
  at::Tensor activity = at::empty({images, n_atoms}, coefficients.options());
  constexpr int64_t kLevels = 4;
  int64_t ceil_log2 = 1;
  if (patches > 2) {
    ceil_log2 = 0;
    while ((int64_t(1) << ceil_log2) < patches) ++ceil_log2;
  }
  const int64_t level_power = std::max<int64_t>(4, ceil_log2 / kLevels);
  const int64_t level_step = int64_t(1) << level_power;
  const int64_t level_mask = level_step - 1;
  AT_DISPATCH_FLOATING_TYPES(coefficients.scalar_type(), "pooled_activity", [&] {
    const int64_t* p = picks.data_ptr<int64_t>();
    const scalar_t* w = coefficients.data_ptr<scalar_t>();
    scalar_t* out = activity.data_ptr<scalar_t>();
    at::parallel_for(0, images, 1, [&](int64_t begin, int64_t end) {
      std::vector<scalar_t> levels(kLevels * n_atoms);
      std::vector<int64_t> atoms(sparsity);
      std::vector<scalar_t> values(sparsity);
      for (int64_t image = begin; image < end; ++image) {
        std::fill(levels.begin(), levels.end(), scalar_t(0));
        scalar_t* first = levels.data();
        auto add_patch = [&](int64_t i) {
          const int64_t row = image * patches + i;
          int64_t distinct = 0;
          for (int64_t step = 0; step < sparsity; ++step) {   // b of each atom picked
            const int64_t atom = p[row * sparsity + step];
            int64_t slot = 0;
            while (slot < distinct && atoms[slot] != atom) ++slot;
            if (slot == distinct) {
              atoms[distinct] = atom;
              values[distinct++] = scalar_t(0);
            }
            values[slot] += w[row * sparsity + step];
          }
          for (int64_t d = 0; d < distinct; ++d) first[atoms[d]] += values[d] * values[d];
        };
        int64_t i = 0;
        while (i + level_step <= patches) {
          for (int64_t j = 0; j < level_step; ++j, ++i) add_patch(i);
          for (int64_t level = 1; level < kLevels; ++level) {
            scalar_t* below = levels.data() + (level - 1) * n_atoms;
            scalar_t* here = levels.data() + level * n_atoms;
            for (int64_t n = 0; n < n_atoms; ++n) {
              here[n] += below[n];
              below[n] = scalar_t(0);
            }
            if ((i & (level_mask << (level * level_power))) != 0) break;
          }
        }
        for (; i < patches; ++i) add_patch(i);
        for (int64_t level = 1; level < kLevels; ++level) {
          const scalar_t* here = levels.data() + level * n_atoms;
          for (int64_t n = 0; n < n_atoms; ++n) first[n] += here[n];
        }
        for (int64_t n = 0; n < n_atoms; ++n) {
          out[image * n_atoms + n] = first[n] / static_cast<scalar_t>(patches);
        }
      }
    });
  });
  return activity;
}

// Bᵀ·R, (N, K): for every atom, Σ c·r_i over the picks of that atom in (patch, step) order, from
// the (M, k) picks and the (M, K) residuals. With ``out`` the sums are added to it, in place:
// calls on consecutive chunks of patches then add up exactly as one call on all of them.
at::Tensor codes_times_residuals(const at::Tensor& picks, const at::Tensor& coefficients,
                                 const at::Tensor& residuals, int64_t n_atoms,
                                 c10::optional<at::Tensor> out) {
  check_cpu_contiguous(residuals, "residuals");
  TORCH_CHECK(residuals.dim() == 2, "residuals must be (M, K)");
  TORCH_CHECK(coefficients.scalar_type() == residuals.scalar_type(),
              "coefficients and residuals must share a dtype");
  TORCH_CHECK(n_atoms >= 1, "the dictionary needs at least one atom");
  const int64_t rows = residuals.size(0), dim = residuals.size(1);
  check_picks(picks, coefficients, rows, n_atoms);
  const int64_t sparsity = picks.size(1);
  at::Tensor product;
  if (out.has_value()) {
    product = *out;
    check_cpu_contiguous(product, "out");
    TORCH_CHECK(product.scalar_type() == residuals.scalar_type() && product.dim() == 2 &&
                    product.size(0) == n_atoms && product.size(1) == dim,
                "out must be (N, K) in the residuals' dtype");
  } else {
    product = at::zeros({n_atoms, dim}, residuals.options());
  }
  AT_DISPATCH_FLOATING_TYPES(residuals.scalar_type(), "codes_times_residuals", [&] {
    const int64_t* p = picks.data_ptr<int64_t>();
    const scalar_t* w = coefficients.data_ptr<scalar_t>();
    const scalar_t* r = residuals.data_ptr<scalar_t>();
    scalar_t* out = product.data_ptr<scalar_t>();
    // Threads split the K columns; each column adds up the picks in the same order.
    at::parallel_for(0, dim, 16, [&](int64_t begin, int64_t end) {
      for (int64_t row = 0; row < rows; ++row) {
        const scalar_t* residual = r + row * dim;
        for (int64_t step = 0; step < sparsity; ++step) {
          const scalar_t weight = w[row * sparsity + step];
          scalar_t* target = out + p[row * sparsity + step] * dim;
          for (int64_t j = begin; j < end; ++j) {
            target[j] = add_weighted(target[j], weight, residual[j]);
          }
        }
      }
    });
  });
  return product;
}

// One dictionary step and the next Gram matrix in one call, so that the GIL stays released from
// start to end (a step of separate Python calls takes it back between them, and then the thread
// that runs the policy meanwhile waits for it at each of its own calls): Bᵀ·R of the chunks'
// picks and residuals, chunk after chunk; Φ += alpha·Bᵀ·R; every atom divided by max(‖φ‖,
// min_norm); and Φ·Φᵀ, returned. The same ATen operations in the same order as
// parallax.coding.dictionary.gradient_step_ followed by parallax.coding.pursuit.gram_matrix.
at::Tensor dictionary_step(at::Tensor dictionary, const std::vector<at::Tensor>& picks,
                           const std::vector<at::Tensor>& coefficients,
                           const std::vector<at::Tensor>& residuals, double alpha,
                           double min_norm) {
  check_cpu_contiguous(dictionary, "dictionary");
  TORCH_CHECK(dictionary.dim() == 2, "dictionary must be (N, K)");
  TORCH_CHECK(!picks.empty() && picks.size() == coefficients.size() &&
                  picks.size() == residuals.size(),
              "picks, coefficients and residuals must be lists of the same chunks, at least one");
  c10::optional<at::Tensor> product;
  for (size_t chunk = 0; chunk < picks.size(); ++chunk) {
    product = codes_times_residuals(picks[chunk].contiguous(), coefficients[chunk].contiguous(),
                                    residuals[chunk].contiguous(), dictionary.size(0), product);
  }
  TORCH_CHECK(product->size(1) == dictionary.size(1), "residuals and dictionary disagree on K");
  dictionary.add_(*product, alpha);
  dictionary.div_(at::linalg_vector_norm(dictionary, 2, at::IntArrayRef{1}, true, c10::nullopt)
                      .clamp_min_(min_norm));
  return at::matmul(dictionary, dictionary.t());
}

// Centred, unit-norm rows along the last axis, near-constant ones exactly 0: the same ATen
// operations in the same order as parallax.coding.retina.zero_mean_unit_norm.
at::Tensor zero_mean_unit_norm(const at::Tensor& vectors, double tolerance) {
  const at::Tensor means = vectors.mean(at::IntArrayRef{-1}, true);
  const at::Tensor centred = vectors.sub(means);
  const at::Tensor norms =
      at::linalg_vector_norm(centred, 2, at::IntArrayRef{-1}, true, c10::nullopt);
  const at::Tensor floor =
      means.abs().mul(tolerance * std::sqrt(static_cast<double>(vectors.size(-1))));
  return centred.mul(at::where(norms.gt(floor), norms.reciprocal(), 0.0));
}

// e (eq. 4) of (B, P, K) patches and residuals, (B,): parallax.coding.dictionary's
// reconstruction_error, operation for operation.
at::Tensor reconstruction_error(const at::Tensor& patches, const at::Tensor& residuals) {
  const at::Tensor patch_energy = patches.square().sum(at::IntArrayRef{-1});
  const at::Tensor residual_energy = residuals.square().sum(at::IntArrayRef{-1});
  const at::Tensor has_energy = patch_energy.gt(0);
  const at::Tensor ratio =
      residual_energy.div(at::where(has_energy, patch_energy, at::ones_like(patch_energy)));
  return at::where(has_energy, ratio, at::zeros_like(ratio)).mean(at::IntArrayRef{1});
}

// One scale's whole encoding of B images in one call, so that the GIL stays released from start
// to end (as separate calls, the two scales' threads each waited for the GIL at every one of
// them): the [I0 ; I(t)] patch pairs γ from the cached I0 patches and the raw I(t) patches
// (parallax.coding.retina.stack_pair), the pursuit (gram_pursuit on γ·Φᵀ), the residuals, θ from
// the picks (pooled_activity) and e. Returns the picks, coefficients, residuals (B·P, K), θ
// (B, N) and e (B,), as ScaleCoder.encode_images computes them from separate calls.
std::vector<at::Tensor> encode_pairs(const at::Tensor& reference, const at::Tensor& raw,
                                     const at::Tensor& dictionary, const at::Tensor& gram,
                                     int64_t sparsity, bool per_half, double tolerance) {
  TORCH_CHECK(reference.dim() == 3 && raw.dim() == 3 && reference.size(0) == raw.size(0) &&
                  reference.size(1) == raw.size(1),
              "reference and raw patches must be (B, P, ·) of the same B and P");
  const at::Tensor pairs =
      per_half ? at::cat({reference, zero_mean_unit_norm(raw, tolerance)}, -1)
               : zero_mean_unit_norm(at::cat({reference, raw}, -1), tolerance);
  const int64_t images = pairs.size(0), patches = pairs.size(1), dim = pairs.size(2);
  const at::Tensor flat = pairs.reshape({images * patches, dim});
  const std::vector<at::Tensor> pursuit =
      gram_pursuit(at::matmul(flat, dictionary.t()), gram.contiguous(), sparsity);
  const at::Tensor residuals =
      residuals_only(flat.contiguous(), dictionary.contiguous(), pursuit[0], pursuit[1]);
  const at::Tensor activity = pooled_activity(pursuit[0], pursuit[1], patches, dictionary.size(0));
  const at::Tensor error =
      reconstruction_error(pairs, residuals.reshape({images, patches, dim}));
  return {pursuit[0], pursuit[1], residuals, activity, error};
}


// One scale's encoding of B images from their pyramid images (B, h, w): the raw patches of
// parallax.coding.retina.extract_patches (the same unfold and reshape), then encode_pairs.
// Returns encode_pairs' five tensors and the raw patches (the next references of the
// consecutive pairing).
std::vector<at::Tensor> encode_scale(const at::Tensor& reference, const at::Tensor& image,
                                     int64_t patch, int64_t stride, const at::Tensor& dictionary,
                                     const at::Tensor& gram, int64_t sparsity, bool per_half,
                                     double tolerance) {
  TORCH_CHECK(image.dim() == 3, "pyramid images must be (B, h, w)");
  const at::Tensor raw = image.unfold(1, patch, stride)
                             .unfold(2, patch, stride)
                             .reshape({image.size(0), -1, patch * patch});
  std::vector<at::Tensor> encoded =
      encode_pairs(reference, raw, dictionary, gram, sparsity, per_half, tolerance);
  encoded.push_back(raw);
  return encoded;
}

// The helper thread: jobs run one at a time, in the order they were handed over. A forked child
// starts its own (a thread does not survive fork); the parent's object is left alone there.
class HelperThread {
 public:
  HelperThread() : pid_(getpid()) {
    std::thread([this] { serve(); }).detach();   // it serves until the process ends
  }
  pid_t pid() const { return pid_; }
  void post(std::function<void()> job) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      jobs_.push_back(std::move(job));
    }
    ready_.notify_one();
  }

 private:
  void serve() {
    // The name parallax-bench's CPU split looks for (parallax.tools.bench.timing).
    pthread_setname_np(pthread_self(), "parallax-scale");
    for (;;) {
      std::function<void()> job;
      {
        std::unique_lock<std::mutex> lock(mutex_);
        ready_.wait(lock, [this] { return !jobs_.empty(); });
        job = std::move(jobs_.front());
        jobs_.pop_front();
      }
      job();
    }
  }
  const pid_t pid_;
  std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<std::function<void()>> jobs_;
};

HelperThread& helper_thread() {
  static std::mutex creating;
  static HelperThread* helper = nullptr;   // never freed: its thread may outlive any owner
  std::lock_guard<std::mutex> lock(creating);
  if (helper == nullptr || helper->pid() != getpid()) helper = new HelperThread();
  return *helper;
}

using Tensors = std::vector<at::Tensor>;

// work() on the helper thread, with the caller's intra-op thread count (per thread under OpenMP
// and MKL: with the caller's, the helper's products and reductions add up as the caller's would)
// and without autograd; its result or its exception through the future. The job drops its
// inputs before it hands the result over, so that the caller drops the last reference to a
// tensor that Python owns (torch.from_numpy's), on its own thread.
std::shared_future<Tensors> on_helper(std::function<Tensors()> work) {
  const int threads = at::get_num_threads();
  auto promise = std::make_shared<std::promise<Tensors>>();
  std::shared_future<Tensors> result = promise->get_future().share();
  helper_thread().post([threads, promise, work = std::move(work)]() mutable {
    try {
      if (at::get_num_threads() != threads) at::set_num_threads(threads);
      at::NoGradGuard no_grad;
      Tensors value = work();
      work = nullptr;
      promise->set_value(std::move(value));
    } catch (...) {
      work = nullptr;
      promise->set_exception(std::current_exception());
    }
  });
  return result;
}

// Every scale's encoding of the same B images in one call: the first scale on this thread, the
// others on the helper thread at the same time (the scales share nothing). Per scale its cached
// I0 patches, its pyramid images, patch side and stride, dictionary and Gram matrix. Returns the
// state θ = [θ¹; θ²; …] (B, N·S), the reward −Σ_j e^j (B,) and each scale's encode_scale
// tensors, as parallax.coding.MultiScaleCoder.encode computes them from separate calls.
std::tuple<at::Tensor, at::Tensor, std::vector<Tensors>> encode_scales(
    const Tensors& references, const Tensors& images, const std::vector<int64_t>& patches,
    const std::vector<int64_t>& strides, const Tensors& dictionaries, const Tensors& grams,
    int64_t sparsity, bool per_half, double tolerance) {
  const size_t scales = references.size();
  TORCH_CHECK(scales >= 1 && images.size() == scales && patches.size() == scales &&
                  strides.size() == scales && dictionaries.size() == scales &&
                  grams.size() == scales,
              "one reference, image, patch side, stride, dictionary and Gram matrix per scale");
  auto scale = [&, per_half, tolerance, sparsity](size_t s) {
    return encode_scale(references[s], images[s], patches[s], strides[s], dictionaries[s],
                        grams[s], sparsity, per_half, tolerance);
  };
  std::vector<std::shared_future<Tensors>> others;
  for (size_t s = 1; s < scales; ++s) {
    others.push_back(on_helper([reference = references[s], image = images[s], patch = patches[s],
                                stride = strides[s], dictionary = dictionaries[s],
                                gram = grams[s], sparsity, per_half, tolerance] {
      return encode_scale(reference, image, patch, stride, dictionary, gram, sparsity, per_half,
                          tolerance);
    }));
  }
  std::vector<Tensors> encoded(scales);
  std::exception_ptr failure;
  try {
    encoded[0] = scale(0);
  } catch (...) {
    failure = std::current_exception();
  }
  for (size_t s = 1; s < scales; ++s) {   // every scale finished before anything is raised
    try {
      encoded[s] = others[s - 1].get();
    } catch (...) {
      if (!failure) failure = std::current_exception();
    }
  }
  if (failure) std::rethrow_exception(failure);
  Tensors activities, errors;
  for (const Tensors& e : encoded) {
    activities.push_back(e[3]);
    errors.push_back(e[4]);
  }
  at::Tensor state = at::cat(activities, 1);
  at::Tensor reward = at::stack(errors).sum(at::IntArrayRef{0}).neg();
  return {state, reward, encoded};
}

// Dictionary steps running on the helper thread; wait() gives their Gram matrices.
class PendingSteps {
 public:
  explicit PendingSteps(std::shared_future<Tensors> grams) : grams_(std::move(grams)) {}
  Tensors wait() const { return grams_.get(); }
  bool done() const {
    return grams_.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
  }

 private:
  std::shared_future<Tensors> grams_;
};

// Each scale's dictionary_step, in scale order, on the helper thread: per scale its dictionary
// (changed in place), its chunks' picks, coefficients and residuals, and its step size. Nothing
// may read or write the dictionaries until wait() has returned.
PendingSteps start_dictionary_steps(const Tensors& dictionaries,
                                    const std::vector<Tensors>& picks,
                                    const std::vector<Tensors>& coefficients,
                                    const std::vector<Tensors>& residuals,
                                    const std::vector<double>& alphas, double min_norm) {
  const size_t scales = dictionaries.size();
  TORCH_CHECK(picks.size() == scales && coefficients.size() == scales &&
                  residuals.size() == scales && alphas.size() == scales,
              "one dictionary, list of chunks and step size per scale");
  return PendingSteps(on_helper([=] {
    Tensors grams;
    for (size_t s = 0; s < scales; ++s) {
      grams.push_back(dictionary_step(dictionaries[s], picks[s], coefficients[s], residuals[s],
                                      alphas[s], min_norm));
    }
    return grams;
  }));
}

}  // namespace

// The GIL is released while they run: they touch tensors only, and the world renders the next
// frames on another thread meanwhile (parallax.envs.rendering).
PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  using release_gil = py::call_guard<py::gil_scoped_release>;
  m.def("gram_pursuit", &gram_pursuit,
        "k steps of Gram-form matching pursuit, patch by patch (paper eq. 1); "
        "correlations are updated in place", release_gil());
  m.def("codes_and_residuals", &codes_and_residuals,
        "dense (M, N) codes and (M, K) residuals from the pursuit's picks", release_gil());
  m.def("residuals_only", &residuals_only,
        "the (M, K) residuals from the pursuit's picks, without the dense codes", release_gil());
  m.def("pooled_activity", &pooled_activity,
        "theta (B, N) from the picks of B images of P patches, summed in torch's order",
        release_gil());
  m.def("codes_times_residuals", &codes_times_residuals,
        "the dictionary gradient's B^T R, (N, K), from the picks and the residuals; added to "
        "out when given", py::arg("picks"), py::arg("coefficients"), py::arg("residuals"),
        py::arg("n_atoms"), py::arg("out") = py::none(), release_gil());
  m.def("dictionary_step", &dictionary_step,
        "one dictionary step in place (B^T R of the chunks, the step, unit-norm atoms) and the "
        "next Gram matrix, returned", py::arg("dictionary"), py::arg("picks"),
        py::arg("coefficients"), py::arg("residuals"), py::arg("alpha"), py::arg("min_norm"),
        release_gil());
  m.def("encode_pairs", &encode_pairs,
        "one scale's encoding in one call: patch pairs, pursuit, residuals, theta from the "
        "picks and e; returns picks, coefficients, residuals, theta, e", py::arg("reference"),
        py::arg("raw"), py::arg("dictionary"), py::arg("gram"), py::arg("sparsity"),
        py::arg("per_half"), py::arg("tolerance"), release_gil());
  m.def("encode_scales", &encode_scales,
        "every scale's encoding of the same images, the first on this thread and the others on "
        "the helper thread; returns theta, the reward and per scale encode_pairs' tensors and "
        "the raw patches", py::arg("references"), py::arg("images"), py::arg("patches"),
        py::arg("strides"), py::arg("dictionaries"), py::arg("grams"), py::arg("sparsity"),
        py::arg("per_half"), py::arg("tolerance"), release_gil());
  py::class_<PendingSteps>(m, "PendingSteps")
      .def("wait", &PendingSteps::wait, "the steps' Gram matrices, once they have finished",
           release_gil())
      .def("done", &PendingSteps::done);
  m.def("start_dictionary_steps", &start_dictionary_steps,
        "each scale's dictionary step on the helper thread, in scale order",
        py::arg("dictionaries"), py::arg("picks"), py::arg("coefficients"), py::arg("residuals"),
        py::arg("alphas"), py::arg("min_norm"), release_gil());
}
