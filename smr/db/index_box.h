// The R-tree's boxes (index::Box, Maheshwari 3.1) and the CRMR's (Box3), one to the other: the
// store indexes ops' ROIs and boxes, and readers of the index judge what it returns as Box3s.
#pragma once

#include "index/box.h"
#include "smr/core/geometry.h"

namespace smr {

inline index::Box to_index(const Box3& b) {
  index::Box out;
  for (int k = 0; k < 3; ++k) {
    out.lo[k] = b.lo[k];
    out.hi[k] = b.hi[k];
  }
  return out;
}

inline Box3 from_index(const index::Box& b) {
  Box3 out;
  for (int k = 0; k < 3; ++k) {
    out.lo[k] = b.lo[k];
    out.hi[k] = b.hi[k];
  }
  return out;
}

}  // namespace smr
