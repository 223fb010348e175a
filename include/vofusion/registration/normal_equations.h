#pragma once
// Gauss-Newton sums of a 6-parameter least-squares problem (J^T W J in its upper triangle, -J^T W r):
// ICP's and the photometric term's, summed per row (icp_association.h, photometric_association.h) and
// joined in a fixed order (see parallelReduce).
#include <Eigen/Core>

namespace vofusion::fusion {

struct NormalSums6 {
  double A[21] = {};  // upper triangle of J^T W J, row by row
  double b[6] = {};   // -J^T W r

  void join(const NormalSums6& o) {
    for (int i = 0; i < 21; ++i) A[i] += o.A[i];
    for (int i = 0; i < 6; ++i) b[i] += o.b[i];
  }
  // The full system, every entry scaled by `scale`.
  void unpack(double scale, Eigen::Matrix<double, 6, 6>& Aout, Eigen::Matrix<double, 6, 1>& bout) const {
    int k = 0;
    for (int i = 0; i < 6; ++i) {
      for (int j = i; j < 6; ++j) Aout(i, j) = Aout(j, i) = scale * A[k++];
      bout[i] = scale * b[i];
    }
  }
};

}  // namespace vofusion::fusion
