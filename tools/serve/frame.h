// The binary frame of a progressive session (docs/serve.md, "Frame"): a JSON header, then the
// keys of the triangles out, the keys, corners and flags of the triangles in, and the morph mesh.
#pragma once

#include <span>
#include <string>

#include <nlohmann/json.hpp>

#include "smr/core/op_source.h"
#include "smr/extract/morph.h"

namespace smr::serve {

inline constexpr std::uint32_t kFrameVersion = 1;

/// Encodes one frame. `header` gets n_out, n_in, n_mv, n_mt and origin added; positions are
/// float32 relative to `origin`; the corners of `in` are read from `source`. `morph` may be null
/// (frame 0: no morph).
std::string encode_frame(const OpSource& source, const Vec3& origin, nlohmann::json header,
                         std::span<const TriRef> out, std::span<const TriRef> in,
                         const MorphMesh* morph);

}  // namespace smr::serve
