// The invariant checker (smr/core/invariants.h, docs/design.md section 8) notices what it is meant
// to: a CRMR damaged on purpose fails the check.
#include <gtest/gtest.h>

#include <utility>

#include "smr/core/invariants.h"
#include "tests/support/datasets.h"
#include "tests/support/sanitized.h"

namespace smr {
namespace {

TEST(Checker, NoticesPreFCornersThatDisagreeWithTheCreator) {
  // A dataset the sanitizer run builds anyway (it has no jacksboro).
  Crmr m = test::dataset(test::kSanitized ? "topobathy" : "jacksboro").crmr;
  Op& op = m.ops.at(m.ops.size() / 2);
  ASSERT_FALSE(op.pre_tris.empty());
  std::swap(op.pre_tris[0].v[0], op.pre_tris[0].v[1]);  // the same corners, other orientation
  EXPECT_FALSE(check_crmr(m).ok());
  std::swap(op.pre_tris[0].v[0], op.pre_tris[0].v[1]);
  op.pre_tris.pop_back();
  EXPECT_FALSE(check_crmr(m).ok());
}

}  // namespace
}  // namespace smr
