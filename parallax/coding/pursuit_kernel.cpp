// Fused Gram-form matching pursuit on the CPU: the paper's eq. 1 (§3.3), plain MP with k steps.
//
// parallax/coding/native.py builds this file on first use (torch.utils.cpp_extension.load);
// parallax/coding/pursuit.py calls it in place of its per-step numpy/torch loop. Patch by
// patch, a row of correlations c = Φ·γ (N values, a few KiB, in L1 cache for all the steps):
//
//     repeat k times:  j = argmax_n |c_n|     (first maximum on ties, a NaN counts as the
//                                              maximum: numpy's argmax)
//                      record j and b = c_j
//                      c ← c − b·G[j]          (G = Φ·Φᵀ, so c stays the residual's correlations)
//
// The update rounds exactly like torch's addcmul_(b, G[j], value=-1) on this CPU: a fused
// multiply-add when torch's kernels use them (PARALLAX_FMA, set by native.py for its AVX2 and
// AVX512 kernels), a multiply then a subtraction otherwise (built with -ffp-contract=off so the
// compiler does not fuse it by itself). The picks and coefficients are then bit-identical to
// those of the torch path; native.py checks that once before it lets the coder use the kernel.

// The few ATen headers it needs rather than <torch/extension.h>: the build takes ~15 s, not ~40.
#include <ATen/Dispatch.h>
#include <ATen/Parallel.h>
#include <ATen/core/Tensor.h>
#include <ATen/ops/empty.h>
#include <torch/csrc/utils/pybind.h>

#include <cmath>
#include <cstdint>
#include <cstring>
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

// Index of the first maximum of |c| over n values, or of the first NaN if there is one.
template <typename T>
int64_t first_abs_argmax(const T* c, int64_t n) {
  using Values = typename Simd<T>::Values;
  using Indices = typename Simd<T>::Indices;
  constexpr int W = sizeof(Values) / sizeof(T);
  // Lane l keeps the first maximum of c[l], c[l + W], c[l + 2W], ... (strict >).
  Values lane_max = Values{} - 1;   // below any |c|
  Indices lane_index = {}, index = {}, lane_nan = {};
  for (int l = 0; l < W; ++l) index[l] = l;
  const int64_t whole = n - n % W;
  for (int64_t j = 0; j < whole; j += W) {
    Values v;
    std::memcpy(&v, c + j, sizeof v);
    const Values magnitude = v < 0 ? -v : v;
    const Indices larger = magnitude > lane_max;
    lane_max = larger ? magnitude : lane_max;
    lane_index = larger ? index : lane_index;
    lane_nan |= magnitude != magnitude;
    index += W;
  }
  // The largest lane maximum; of equal ones, the first index.
  T best = T(-1);
  int64_t best_index = 0;
  bool any_nan = false;
  for (int l = 0; l < W; ++l) {
    any_nan |= lane_nan[l] != 0;
    if (lane_max[l] > best || (lane_max[l] == best && lane_index[l] < best_index)) {
      best = lane_max[l];
      best_index = lane_index[l];
    }
  }
  if (any_nan) {
    for (int64_t j = 0; j < whole; ++j) {
      if (std::isnan(c[j])) return j;
    }
  }
  for (int64_t j = whole; j < n; ++j) {   // the tail comes after every lane's index
    const T magnitude = std::abs(c[j]);
    if (std::isnan(magnitude)) return j;
    if (magnitude > best) {
      best = magnitude;
      best_index = j;
    }
  }
  return best_index;
}

template <typename T>
void pursue_rows(T* correlations, const T* gram, int64_t n_atoms, int64_t sparsity,
                 int64_t* picks, T* coefficients, int64_t begin, int64_t end) {
  for (int64_t row = begin; row < end; ++row) {
    T* c = correlations + row * n_atoms;
    for (int64_t step = 0; step < sparsity; ++step) {
      const int64_t pick = first_abs_argmax(c, n_atoms);
      const T coefficient = c[pick];
      picks[row * sparsity + step] = pick;
      coefficients[row * sparsity + step] = coefficient;
      const T* g = gram + pick * n_atoms;
      for (int64_t j = 0; j < n_atoms; ++j) {
        c[j] = subtract_scaled(c[j], coefficient, g[j]);
      }
    }
  }
}

// (M, N) correlations, updated in place, and the (N, N) Gram matrix → (M, k) int64 picks and
// (M, k) coefficients.
std::vector<at::Tensor> gram_pursuit(at::Tensor correlations, const at::Tensor& gram,
                                     int64_t sparsity) {
  TORCH_CHECK(correlations.device().is_cpu() && gram.device().is_cpu(),
              "gram_pursuit runs on CPU tensors");
  TORCH_CHECK(correlations.dim() == 2 && gram.dim() == 2 && gram.size(0) == gram.size(1) &&
                  gram.size(0) == correlations.size(1),
              "correlations must be (M, N) and gram (N, N)");
  TORCH_CHECK(correlations.scalar_type() == gram.scalar_type(),
              "correlations and gram must share a dtype");
  TORCH_CHECK(correlations.is_contiguous() && gram.is_contiguous(),
              "correlations and gram must be contiguous");
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

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("gram_pursuit", &gram_pursuit,
        "k steps of Gram-form matching pursuit, patch by patch (paper eq. 1); "
        "correlations are updated in place");
}
