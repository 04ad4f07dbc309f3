// smrdb extract --algorithm selective: Kim & Lee's truly selective refinement of a mesh database
// (smr/extract/selective.h), read through the database's page cache.
#include <nlohmann/json.hpp>

#include "smr/extract/selective.h"
#include "tools/commands.h"
#include "tools/report_json.h"

namespace smr::tools {

nlohmann::json run_selective(const Database& db, const Rcf& rcf, const ExtractArgs& a) {
  nlohmann::json report;
  // The hierarchy and the fundamental cut vertices: one pass over every op (selective.h).
  const std::shared_ptr<const SelectiveIndex> index = SelectiveIndex::build(db);
  const SplitScheme scheme =
      a.split_scheme.empty() ? SplitScheme::kTrulySelective
                             : SelectiveRefinement::parse_scheme(a.split_scheme, "--split-scheme");
  const SelectiveExtraction e = extract_selective(db, index, rcf, scheme);
  report["rcf"] = rcf.describe();
  report["selective"] = e.stats;
  report["selective"]["scheme"] = SelectiveRefinement::scheme_name(scheme);
  report["selective"]["index"] = index->stats();
  report["selective"]["error_bound"] =
      "each output triangle is a source triangle with its corners moved to their active "
      "ancestors: it and its source triangle are within displacement_bound of each other "
      "(two-sided); the ops' own Hausdorff bounds do not carry over";
  // What the CLI's summary line reads: X is the splits made.
  report["extraction"] = {{"algorithm", "selective"}, {"x", e.stats.splits}};
  report["io"] = db.stats();
  write_output(db, e.mesh, a, report);
  return report;
}

}  // namespace smr::tools
