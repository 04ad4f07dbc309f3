// Internal: the advancing-front surface expansion shared by both extraction algorithms.
#pragma once

#include <span>

#include "smr/extract/extract.h"

namespace smr {

/// Expands X (minimal surface: ancestor-closed X, fixed) or X+ (reduced: grows as coarser
/// versions are needed, with the domain test for starting points).
Extraction run_expansion(const OpSource& source, std::span<const OpId> x, bool reduced,
                         const ExpansionOptions& options);

}  // namespace smr
