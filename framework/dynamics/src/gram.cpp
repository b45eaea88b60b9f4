// exid — fast accumulation of W^T W (see GramAccumulator in dynamics.hpp).
//
// Rows are grouped by their first non-zero column s; a group's buffered rows B (k x m, m = cols-s,
// row-major, zero-padded to a multiple of 4) are added to the lower triangle of the trailing
// block: Acc[s+i][s+j] += sum_r B[r][i] B[r][j], j <= i. The block update is one of the hot
// kernels (kernel_table.hpp): portable in kernels_portable.cpp, AVX2 + FMA in kernels_avx2.cpp.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "kernel_table.hpp"

namespace exid {

namespace {

constexpr int kBatch = 64;

inline int roundUp4(int x) { return (x + 3) & ~3; }

}  // namespace

struct GramAccumulator::Impl {
  int c = 0, ld = 0;
  long rows = 0;
  std::vector<double> acc;               // c x ld, row-major, lower triangle used
  std::vector<std::vector<double>> buf;  // per first non-zero column
  std::vector<int> count;
  Eigen::MatrixXd M;
  bool dirty = true;

  void init(int cols) {
    c = cols;
    ld = roundUp4(cols) + 4;
    acc.assign(static_cast<size_t>(c) * static_cast<size_t>(ld), 0.0);
    buf.assign(static_cast<size_t>(c), {});
    count.assign(static_cast<size_t>(c), 0);
    M.setZero(c, c);
    rows = 0;
    dirty = true;
  }
  void flush(int s) {
    const int k = count[static_cast<size_t>(s)];
    if (k == 0) return;
    const int m = c - s;
    double* A = acc.data() + static_cast<long>(s) * ld + s;
    const double* B = buf[static_cast<size_t>(s)].data();
    detail::kernels().gram(A, ld, B, roundUp4(m), k, m);
    count[static_cast<size_t>(s)] = 0;
  }
  void addRow(const double* x, long stride, double w) {
    int s = 0;
    while (s < c && x[s * stride] == 0.0) ++s;
    if (s == c) return;
    const int m = c - s, ldb = roundUp4(m);
    std::vector<double>& b = buf[static_cast<size_t>(s)];
    if (b.empty()) b.assign(static_cast<size_t>(kBatch) * static_cast<size_t>(ldb), 0.0);
    double* row = b.data() + static_cast<long>(count[static_cast<size_t>(s)]) * ldb;
    for (int j = 0; j < m; ++j) row[j] = w * x[(s + j) * stride];
    if (++count[static_cast<size_t>(s)] == kBatch) flush(s);
  }
};

GramAccumulator::GramAccumulator(int cols) : impl_(new Impl) { impl_->init(std::max(cols, 0)); }
GramAccumulator::~GramAccumulator() = default;
GramAccumulator::GramAccumulator(GramAccumulator&&) noexcept = default;
GramAccumulator& GramAccumulator::operator=(GramAccumulator&&) noexcept = default;

void GramAccumulator::reset(int cols) {
  if (cols >= 0 && cols != impl_->c) {
    impl_->init(cols);
    return;
  }
  std::fill(impl_->acc.begin(), impl_->acc.end(), 0.0);
  std::fill(impl_->count.begin(), impl_->count.end(), 0);
  impl_->rows = 0;
  impl_->dirty = true;
}

void GramAccumulator::add(const Eigen::Ref<const Eigen::MatrixXd>& rows) { addWeighted(rows, 1.0); }

void GramAccumulator::addWeighted(const Eigen::Ref<const Eigen::MatrixXd>& rows, double w) {
  if (rows.cols() != impl_->c)  // the message is built only on failure (hot path)
    throw Error("GramAccumulator::add: " + std::to_string(rows.cols()) + " columns (expected " +
                std::to_string(impl_->c) + ")");
  check(w >= 0.0, "GramAccumulator::addWeighted: negative weight");
  const double sw = std::sqrt(w);
  const long stride = rows.outerStride();  // column-major: element (r, j) at r + j*stride
  for (Eigen::Index r = 0; r < rows.rows(); ++r) impl_->addRow(rows.data() + r, stride, sw);
  impl_->rows += rows.rows();
  impl_->dirty = true;
}

const Eigen::MatrixXd& GramAccumulator::matrix() {
  Impl& I = *impl_;
  if (I.dirty) {
    for (int s = 0; s < I.c; ++s) I.flush(s);
    for (int i = 0; i < I.c; ++i)
      for (int j = 0; j <= i; ++j)
        I.M(i, j) = I.M(j, i) =
            I.acc[static_cast<size_t>(i) * static_cast<size_t>(I.ld) + static_cast<size_t>(j)];
    I.dirty = false;
  }
  return I.M;
}

int GramAccumulator::cols() const { return impl_->c; }
long GramAccumulator::rowsAdded() const { return impl_->rows; }

}  // namespace exid
