#include "smr/core/op_source.h"

#include <algorithm>

namespace smr {

double error_at(const CrmrInfo& info, double res) {
  const double span = info.err0 - info.err_final;
  if (span <= 0.0) return info.err_final;
  return info.err_final + (1.0 - res) * span;
}

double resolution_of(const CrmrInfo& info, double error) {
  const double span = info.err0 - info.err_final;
  if (span <= 0.0) return 1.0;
  return std::clamp(1.0 - (error - info.err_final) / span, 0.0, 1.0);
}

FragmentTriangle OpSource::triangle(TriRef t) const {
  return op(t.op)->triangle(t.index);
}

double OpSource::error_at(double res) const {
  return smr::error_at(info(), res);
}
double OpSource::resolution_of(double error) const {
  return smr::resolution_of(info(), error);
}

}  // namespace smr
