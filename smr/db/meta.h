// The meta record's JSON pieces (tables.h: the record the writer puts last and the reader parses
// first): the model's header and vectors. Internal to smr/db.
#pragma once

#include <nlohmann/json.hpp>

#include "smr/core/op_source.h"

namespace smr {

nlohmann::json vec_json(const Vec3& v);
Vec3 json_vec(const nlohmann::json& j);

nlohmann::json info_json(const CrmrInfo& info);
CrmrInfo json_info(const nlohmann::json& j);

}  // namespace smr
