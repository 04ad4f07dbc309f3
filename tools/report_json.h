// The one JSON writer of each report and stats struct `--json` prints: every key is named once,
// here. nlohmann::json finds them by argument-dependent lookup (`json j = stats;`).
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "smr/db/database.h"
#include "smr/db/verify.h"
#include "smr/db/writer.h"
#include "smr/extract/extract.h"
#include "smr/extract/selective.h"
#include "smr/extract/session.h"
#include "smr/ingest/ingest.h"

namespace smr {

// ---- ingest
void to_json(nlohmann::json& j, const MeshReport& r);       // a mesh read whole: "input"
void to_json(nlohmann::json& j, const QemPmStats& s);       // "simplification"
void to_json(nlohmann::json& j, const BlockPmStats& s);     // "blocks" (meshes)
void to_json(nlohmann::json& j, const BlockTinStats& s);    // "blocks" (DEMs)
void to_json(nlohmann::json& j, const GreedyTinReport& r);  // "input"
void to_json(nlohmann::json& j, const BlockTinReport& r);   // "input"
void to_json(nlohmann::json& j, const CrmrSummary& s);      // "crmr"
void to_json(nlohmann::json& j, const WriteReport& w);      // "database"
// ---- extract, verify
void to_json(nlohmann::json& j, const ExtractStats& s);   // "extraction"
void to_json(nlohmann::json& j, const DatabaseStats& s);  // "io"
void to_json(nlohmann::json& j, const VerifyReport& r);
void to_json(nlohmann::json& j, const FrameStats& s);      // a session update: flythrough, "budget"
void to_json(nlohmann::json& j, const SelectiveStats& s);  // "selective" (--algorithm selective)
void to_json(nlohmann::json& j, const SelectiveIndex::Stats& s);  // its "index"

namespace tools {

/// The report of an ingest: input, the builder's section, crmr, database.
nlohmann::json ingest_json(const IngestReport& r, const std::string& input,
                           const std::string& db_path, const IngestOptions& options);

/// Prints `report` on stdout when `json`.
void print_report(const nlohmann::json& report, bool json);

}  // namespace tools
}  // namespace smr
