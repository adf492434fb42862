// Fused normal equations of the key-term separated regression (Vörös 2016, eqs. 15-28).
//
// For each record of a batch and the current estimates, one pass over time computes the
// internal signals v (eq. 1) and x (eq. 6), the switching variables g1, g2 (eqs. 10-11),
// the corrected output yc (eq. 25) and the regressors phi (eq. 17), and accumulates the
// two diagonal blocks of the Gram matrix phi^T phi, the right-hand sides phi^T yc and
// yc^T yc, without ever storing phi. `kLanes` records (4 or 8) share one pass, one per
// SIMD lane, and the batch is split over threads.
//
// Block 1 holds the NS and LD columns and the cL column (all carry g1); block 2 the mR
// and C columns (they carry g2); g1 g2 = 0, so the blocks are all of phi^T phi.
// With `first` set, the pass is the paper's first iteration: v = u, x = y (measured),
// unit slopes in the breakpoint columns. The Python side (jaxcascade/_fused) is the
// reference for every formula here: jaxcascade/_regression.py.
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

// One record per SIMD lane: 8 with AVX-512 (the same arithmetic per record, in twice the
// lanes: twice the Gram updates per instruction where the cores have 512-bit units), 4
// with AVX2 or less (GCC splits a wider vector into what the target has).
#if defined(__AVX512F__)
constexpr int kLanes = 8;
#else
constexpr int kLanes = 4;
#endif
typedef double vd __attribute__((vector_size(8 * kLanes)));
constexpr int kMaxColumns = 64;  // block-1 columns; the Python side checks the orders
constexpr int kMaxLag = 16;      // r and p
constexpr int64_t kBlock = 32;   // samples buffered per register-tiled Gram update
constexpr int64_t kMaxWidth = (kMaxColumns + 1 + 3) / 4 * 4;

typedef long long vm __attribute__((vector_size(8 * kLanes)));  // lane masks: all ones or 0

inline vd splat(double a) {
  vd out;
  for (int l = 0; l < kLanes; ++l) out[l] = a;
  return out;
}
// Where s < 0: the paper's h (eq. 4) as a lane mask.
inline vm negative(vd s) { return s < splat(0.0); }
// x where the mask is set, else 0 (the product of x with h, exactly, up to the sign of 0).
inline vd keep(vm mask, vd x) { return (vd)(mask & (vm)x); }

// Model orders, known at compile time (`Fixed`, so that every loop over columns unrolls
// and the regressors live in registers) or at run time (`Dynamic`).
template <int NR, int NL, int R, int PP>
struct Fixed {
  static constexpr int64_t nR = NR, nL = NL, r = R, p = PP;
};
struct Dynamic {
  int64_t nR, nL, r, p;
};
template <class O>
int64_t size(const O& o) { return o.nR + o.nR - 1 + o.nL + o.nL - 1 + (o.r - 1) + o.p + 3; }

// Adds `block` buffered rows into the Gram tile of rows c .. c + Rows - 1 and columns
// d .. d + Cols - 1, its sums held in registers over the block. Every entry is summed over
// the samples in the same order whatever the tile's shape.
template <int Rows, int Cols>
inline void tile(vd* G, const vd* rows_, int64_t W, int64_t block, int64_t c, int64_t d) {
  vd s[Rows][Cols];
  for (int i = 0; i < Rows; ++i)
    for (int j = 0; j < Cols; ++j) s[i][j] = G[(c + i) * W + d + j];
  for (int64_t k = 0; k < block; ++k) {
    const vd* row = rows_ + k * W;
    for (int i = 0; i < Rows; ++i) {
      const vd x = row[c + i];
      for (int j = 0; j < Cols; ++j) s[i][j] += x * row[d + j];
    }
  }
  for (int i = 0; i < Rows; ++i)
    for (int j = 0; j < Cols; ++j) G[(c + i) * W + d + j] = s[i][j];
}

// Records [b0, b0 + kLanes) of the batch (indices past the end repeat the last record).
// `scratch` holds u and y of these records, interleaved by lane (2 n vectors), then
// the Gram matrix and the row buffer of block 1 (`scratch_size`).
template <bool First, class O>
void group(const double* u, const double* y, const double* params, int64_t batch, int64_t n,
           const O o, int64_t b0, vd* scratch, double* gram1, double* rhs1, double* gram2,
           double* rhs2, double* ycc) {
  const int64_t P = size(o), K = P - 2;
  int64_t rows[kLanes];
  for (int l = 0; l < kLanes; ++l) rows[l] = std::min(b0 + l, batch - 1);
  vd* us = scratch;
  vd* ys = scratch + n;
  // Interleaved sample by sample (each vector written whole, once), not lane by lane
  // (every lane's pass would touch every vector of `us` and `ys` again).
  const double* ur[kLanes];
  const double* yr[kLanes];
  for (int l = 0; l < kLanes; ++l) {
    ur[l] = u + rows[l] * n;
    yr[l] = y + rows[l] * n;
  }
  for (int64_t t = 0; t < n; ++t) {
    vd ut, yt;
    for (int l = 0; l < kLanes; ++l) {
      ut[l] = ur[l][t];
      yt[l] = yr[l][t];
    }
    us[t] = ut;
    ys[t] = yt;
  }
  // Parameters, one vector per parameter (lane = record).
  vd theta[kMaxColumns + 3];
  for (int64_t i = 0; i < P; ++i)
    for (int l = 0; l < kLanes; ++l) theta[i][l] = params[rows[l] * P + i];
  const vd* MR = theta;
  const vd* DR = MR + o.nR;
  const vd* ML = DR + (o.nR - 1);
  const vd* DL = ML + o.nL;
  const vd* a = DL + (o.nL - 1);
  const vd* b = a + (o.r - 1);
  const vd one = splat(1.0), zero = splat(0.0);
  const vd cL = theta[P - 3], mR = theta[P - 2], cR = theta[P - 1];
  // h(n / mR) = h(n * (1 / mR)): same sign, without a division per sample.
  const vd mRcR = mR * cR, inv_mR = one / mR;
  // Breakpoint-column values -M (eq. 17), unit slopes in the first iteration.
  vd minus_MR[kMaxColumns], minus_ML[kMaxColumns];
  for (int64_t i = 0; i < o.nR; ++i) minus_MR[i] = First ? -one : -MR[i];
  for (int64_t j = 0; j < o.nL; ++j) minus_ML[j] = First ? -one : -ML[j];

  // Block 1 is accumulated as the Gram matrix of the extended rows [phi, yc], padded
  // with zero columns to a multiple of 4 (`W`): its last row holds phi^T yc and yc^T yc.
  // Rows are buffered `kBlock` samples at a time, then added in 2 x 4 register tiles,
  // each tile's eight sums kept in registers over the block (a small syrk).
  const int64_t W = (K + 1 + 3) / 4 * 4;
  vd* G = scratch + 2 * n;        // W x W, lower part used
  vd* rows_ = G + W * W;          // kBlock x W
  for (int64_t i = 0; i < W * W; ++i) G[i] = zero;
  for (int64_t i = 0; i < kBlock * W; ++i) rows_[i] = zero;
  vd G2[3] = {}, r2[2] = {};
  vd v_past[kMaxLag] = {}, x_past[kMaxLag] = {};  // v(t-1), v(t-2), ...; x(t-1), ...
  vd u_prev = zero, y_prev = zero;

  for (int64_t t0 = 0; t0 < n; t0 += kBlock) {
  const int64_t block = std::min<int64_t>(kBlock, n - t0);
  for (int64_t t = t0; t < t0 + block; ++t) {
    vd* phi = rows_ + (t - t0) * W;
    const vd u_t = us[t], y_t = ys[t];
    vd x_t;
    if (First) {
      x_t = y_t;
    } else {  // eq. 6 with a1 = 1
      x_t = v_past[0];
      for (int64_t i = 1; i < o.r; ++i) x_t += a[i - 1] * v_past[i];
      for (int64_t j = 0; j < o.p; ++j) x_t -= b[j] * x_past[j];
    }
    // eqs. 10-11 with mL = 1; the left line wins where both hold.
    const vm g1 = negative(x_t + cL - y_prev);
    const vm g2 = negative((y_prev - mR * x_t + mRcR) * inv_mR) & ~g1;
    const vd yc = y_t - keep(~(g1 | g2), y_prev);  // eq. 25
    // eq. 17, NS and LD columns, with u1 = u(t-1), all carrying g1.
    const vd u1 = u_prev;
    int64_t k = 0;
    vm right[kMaxColumns], left[kMaxColumns];  // h(DR_i - u1), h(u1 - DL_j), with g1
    for (int64_t i = 0; i < o.nR; ++i) right[i] = negative((i == 0 ? zero : DR[i - 1]) - u1) & g1;
    for (int64_t j = 0; j < o.nL; ++j) left[j] = negative(u1 - (j == 0 ? zero : DL[j - 1])) & g1;
    for (int64_t i = 0; i < o.nR; ++i) phi[k++] = keep(right[i], u1);
    for (int64_t i = 1; i < o.nR; ++i) phi[k++] = keep(right[i], minus_MR[i]);
    for (int64_t j = 0; j < o.nL; ++j) phi[k++] = keep(left[j], u1);
    for (int64_t j = 1; j < o.nL; ++j) phi[k++] = keep(left[j], minus_ML[j]);
    for (int64_t i = 2; i <= o.r; ++i) phi[k++] = keep(g1, v_past[i - 1]);
    for (int64_t j = 1; j <= o.p; ++j) phi[k++] = keep(g1, -x_past[j - 1]);
    phi[K - 1] = keep(g1, one);
    phi[K] = yc;
    // Block 2: columns x g2 and -g2.
    const vd q0 = keep(g2, x_t), q1 = keep(g2, -one);
    G2[0] += q0 * q0;
    G2[1] += q1 * q0;
    G2[2] += q1 * q1;
    r2[0] += q0 * yc;
    r2[1] += q1 * yc;
    // Advance the signals: v(t) = NS(u(t)) (eq. 1), or u(t) in the first iteration.
    vd v_t;
    if (First) {
      v_t = u_t;
    } else {
      // eq. 1: h(D - u)(u - D) = max(u - D, 0) on the right, min(u - D, 0) on the left
      v_t = zero;
      for (int64_t i = 0; i < o.nR; ++i) {
        const vd d = u_t - (i == 0 ? zero : DR[i - 1]);
        v_t += MR[i] * keep(negative(-d), d);
      }
      for (int64_t j = 0; j < o.nL; ++j) {
        const vd d = u_t - (j == 0 ? zero : DL[j - 1]);
        v_t += ML[j] * keep(negative(d), d);
      }
    }
    for (int64_t i = (o.r > 1 ? o.r : 1) - 1; i > 0; --i) v_past[i] = v_past[i - 1];
    v_past[0] = v_t;
    for (int64_t j = o.p - 1; j > 0; --j) x_past[j] = x_past[j - 1];
    if (o.p > 0) x_past[0] = x_t;
    u_prev = u_t;
    y_prev = y_t;
  }
  // The block's rows into the Gram matrix: tiles of rows (c, c + 1) x columns
  // (d .. d + 3) over the rows in use (the K columns and yc), narrowed where they would
  // reach only the upper triangle or the padding (`tile`).
  for (int64_t c = 0; c <= K; c += 2) {
    const bool pair = c + 1 <= K;
    const int64_t last = pair ? c + 1 : c;  // the tile's last row
    for (int64_t d = 0; d <= last; d += 4) {
      const bool narrow = last - d < 2;  // columns d + 2, d + 3 all above the diagonal
      if (pair)
        narrow ? tile<2, 2>(G, rows_, W, block, c, d) : tile<2, 4>(G, rows_, W, block, c, d);
      else
        narrow ? tile<1, 2>(G, rows_, W, block, c, d) : tile<1, 4>(G, rows_, W, block, c, d);
    }
  }
  }
  for (int l = 0; l < kLanes && b0 + l < batch; ++l) {
    const int64_t b = b0 + l;
    for (int64_t c = 0; c < K; ++c) {
      for (int64_t d = 0; d <= c; ++d) {
        gram1[(b * K + c) * K + d] = G[c * W + d][l];
        gram1[(b * K + d) * K + c] = G[c * W + d][l];
      }
      rhs1[b * K + c] = G[K * W + c][l];
    }
    gram2[b * 4 + 0] = G2[0][l];
    gram2[b * 4 + 1] = G2[1][l];
    gram2[b * 4 + 2] = G2[1][l];
    gram2[b * 4 + 3] = G2[2][l];
    rhs2[b * 2 + 0] = r2[0][l];
    rhs2[b * 2 + 1] = r2[1][l];
    ycc[b] = G[K * W + K][l];
  }
}

// One group with the orders' fastest instantiation: the paper's orders compile to
// straight-line code; any other orders run the same code with run-time loop bounds.
template <bool First>
void dispatch(const double* u, const double* y, const double* params, int64_t batch,
              int64_t n, const Dynamic& o, int64_t b0, vd* scratch, double* gram1,
              double* rhs1, double* gram2, double* rhs2, double* ycc) {
  if (o.nR == 2 && o.nL == 2 && o.r == 2 && o.p == 2)
    group<First>(u, y, params, batch, n, Fixed<2, 2, 2, 2>{}, b0, scratch, gram1, rhs1, gram2,
                 rhs2, ycc);
  else
    group<First>(u, y, params, batch, n, o, b0, scratch, gram1, rhs1, gram2, rhs2, ycc);
}

template <class Dims>
std::string shape(const Dims& dims) {
  std::string out = "(";
  for (size_t i = 0; i < dims.size(); ++i) out += (i ? ", " : "") + std::to_string(dims[i]);
  return out + (dims.size() == 1 ? ",)" : ")");
}

// Calls running now, in any thread of the process: the cores are shared among them. A
// batch split over host threads (`_batching.host_threads`) runs one call per thread at
// once, and each call then takes its share of the cores instead of all of them (two
// calls of two threads each on two cores ran about 10% slower than of one each).
std::atomic<int64_t> active_calls{0};

int64_t thread_count(int64_t groups, int64_t concurrent) {
  int64_t threads = std::thread::hardware_concurrency();
  if (const char* env = std::getenv("JAXCASCADE_THREADS")) threads = std::atoll(env);
  threads /= std::max<int64_t>(concurrent, 1);
  return std::max<int64_t>(1, std::min(threads, groups));
}

struct ActiveCall {  // counts this call among the running ones while it lives
  int64_t concurrent;
  ActiveCall() : concurrent(active_calls.fetch_add(1) + 1) {}
  ~ActiveCall() { active_calls.fetch_sub(1); }
};

ffi::Error NormalEquationsImpl(ffi::Buffer<ffi::F64> u, ffi::Buffer<ffi::F64> y,
                               ffi::Buffer<ffi::F64> params, int64_t nR, int64_t nL,
                               int64_t r, int64_t p, int64_t first,
                               ffi::ResultBuffer<ffi::F64> gram1,
                               ffi::ResultBuffer<ffi::F64> rhs1,
                               ffi::ResultBuffer<ffi::F64> gram2,
                               ffi::ResultBuffer<ffi::F64> rhs2,
                               ffi::ResultBuffer<ffi::F64> ycc) {
  const Dynamic o{nR, nL, r, p};
  if (nR < 1 || nL < 1 || r < 1 || p < 0 || r > kMaxLag || p > kMaxLag ||
      size(o) - 2 > kMaxColumns)
    return ffi::Error::InvalidArgument("normal_equations: unsupported orders");
  // Every buffer's shape is checked against u's before anything is read or written: a
  // mismatch (2-D arrays where one record is expected, y shorter than u, parameters of
  // other orders) must be an error, not a read past a buffer's end.
  const auto dims = u.dimensions();
  if (dims.size() < 1) return ffi::Error::InvalidArgument("normal_equations: u needs an axis");
  const int64_t n = dims.back();
  const auto ydims = y.dimensions();
  if (ydims.size() != dims.size() || !std::equal(dims.begin(), dims.end(), ydims.begin()))
    return ffi::Error::InvalidArgument("normal_equations: u and y must have the same shape, "
                                       "got " + shape(dims) + " and " + shape(ydims));
  const auto pdims = params.dimensions();
  if (pdims.size() != dims.size() || pdims.back() != size(o) ||
      !std::equal(dims.begin(), dims.end() - 1, pdims.begin()))
    return ffi::Error::InvalidArgument(
        "normal_equations: params must have shape (batch..., " + std::to_string(size(o)) +
        ") for u of shape " + shape(dims) + ", got " + shape(pdims));
  int64_t batch = 1;
  for (size_t i = 0; i + 1 < dims.size(); ++i) batch *= dims[i];
  const int64_t K = size(o) - 2;
  if (gram1->element_count() != static_cast<size_t>(batch * K * K) ||
      rhs1->element_count() != static_cast<size_t>(batch * K) ||
      gram2->element_count() != static_cast<size_t>(batch * 4) ||
      rhs2->element_count() != static_cast<size_t>(batch * 2) ||
      ycc->element_count() != static_cast<size_t>(batch))
    return ffi::Error::InvalidArgument(
        "normal_equations: the results do not hold a batch of " + std::to_string(batch) +
        " records of " + std::to_string(K) + " block-1 columns");
  if (n == 0) {  // an empty record: every sum is 0
    for (auto* out : {&gram1, &rhs1, &gram2, &rhs2, &ycc})
      std::fill_n((*out)->typed_data(), (*out)->element_count(), 0.0);
    return ffi::Error::Success();
  }
  const int64_t groups = (batch + kLanes - 1) / kLanes;
  const ActiveCall call;
  const int64_t threads = thread_count(groups, call.concurrent);
  auto work = [&](int64_t worker) {
    std::vector<vd> scratch(2 * n + kMaxWidth * kMaxWidth + kBlock * kMaxWidth);
    for (int64_t g = worker; g < groups; g += threads) {
      auto run = first ? dispatch<true> : dispatch<false>;
      run(u.typed_data(), y.typed_data(), params.typed_data(), batch, n, o, g * kLanes,
          scratch.data(), gram1->typed_data(), rhs1->typed_data(), gram2->typed_data(),
          rhs2->typed_data(), ycc->typed_data());
    }
  };
  std::vector<std::thread> pool;
  for (int64_t w = 1; w < threads; ++w) pool.emplace_back(work, w);
  work(0);
  for (auto& thread : pool) thread.join();
  return ffi::Error::Success();
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(JaxcascadeNormalEquations, NormalEquationsImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Attr<int64_t>("nR")
                                  .Attr<int64_t>("nL")
                                  .Attr<int64_t>("r")
                                  .Attr<int64_t>("p")
                                  .Attr<int64_t>("first")
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>());
