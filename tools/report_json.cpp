#include "tools/report_json.h"

#include <algorithm>
#include <iostream>
#include <variant>

namespace smr {

using nlohmann::json;

void to_json(json& j, const MeshReport& r) {
  j = {{"vertices", r.vertices},     {"triangles", r.faces},
       {"components", r.components}, {"boundary_edges", r.boundary_edges},
       {"repairs", r.repairs()},     {"summary", r.summary()}};
}

void to_json(json& j, const QemPmStats& s) {
  j = {{"collapses", s.collapses},
       {"spawned_components", s.spawned_components},
       {"base_vertices", s.base_vertices},
       {"base_triangles", s.base_triangles},
       {"bounds_computed", s.bounds_computed},
       {"bounds_ahead", s.bounds_ahead},
       {"bounds_ahead_used", s.bounds_ahead_used},
       {"rejected_link", s.rejected_link},
       {"rejected_flip", s.rejected_flip},
       {"rejected_boundary", s.rejected_boundary},
       {"rejected_intersection", s.rejected_intersection},
       {"rejected_mixed_levels", s.rejected_mixed_levels}};
}

void to_json(json& j, const BlockPmStats& s) {
  j = {{"leaf_blocks", s.leaf_blocks},
       {"levels", s.levels},
       {"rounds", s.rounds},
       {"dag_height", s.dag_height},
       {"collapses", s.collapses},
       {"base_vertices", s.base_vertices},
       {"base_triangles", s.base_triangles},
       {"rejected_intersection", s.rejected_intersection},
       {"max_block_triangles", s.max_block_triangles},
       {"max_handed_triangles", s.max_handed_triangles},
       {"seconds",
        {{"sort", s.seconds_sort},
         {"blocks", s.seconds_blocks},
         {"blocks_tail", s.seconds_tail},
         {"assemble", s.seconds_assemble},
         {"assembly_join", s.seconds_join},
         {"assembly_emit", s.seconds_emit}}}};
}

void to_json(json& j, const BlockTinStats& s) {
  j = {{"leaf_blocks", s.leaf_blocks},
       {"levels", s.levels},
       {"rounds", s.rounds},
       {"dag_height", s.dag_height},
       {"removals", s.removals},
       {"finest_vertices", s.finest_vertices},
       {"base_vertices", s.base_vertices},
       {"non_delaunay_holes", s.non_delaunay_holes},
       {"delaunay_flips", s.delaunay_flips},
       {"delaunay_insertions", s.delaunay_insertions},
       {"level0_interleaved", s.level0_interleaved},
       {"level0_restarts", s.level0_restarts},
       {"exact_levels", s.exact_levels},
       {"samples_rescanned", s.samples_rescanned},
       {"samples_scanned", s.samples_scanned},
       {"plans", s.plans},
       {"triangles_made", s.triangles_made},
       {"record_mb", double(s.record_bytes) / double(1 << 20)},
       {"seconds",
        {{"survey", s.seconds_survey},
         {"read", s.seconds_read},
         {"greedy", s.seconds_greedy},
         {"delaunay", s.seconds_delaunay},
         {"level0", s.seconds_level0},
         {"leaves", s.seconds_leaves},
         {"upper", s.seconds_upper},
         {"assemble", s.seconds_assemble},
         {"assembly_feed", s.seconds_feed},
         {"assembly_join", s.seconds_join},
         {"assembly_emit", s.seconds_emit}}}};
}

void to_json(json& j, const GreedyTinReport& r) {
  j = {{"width", r.width},   {"height", r.height},         {"samples", r.samples},
       {"nodata", r.nodata}, {"geographic", r.geographic}, {"read_seconds", r.read_seconds}};
}

void to_json(json& j, const BlockTinReport& r) {
  j = {{"width", r.width},
       {"height", r.height},
       {"samples", r.stats.samples},
       {"geographic", r.geographic},
       {"largest_window_samples", r.stats.max_block_samples}};
}

void to_json(json& j, const CrmrSummary& s) {
  j = {{"ops", s.ops},
       {"fragment_triangles", s.fragment_triangles},
       {"vertices", s.vertices},
       {"finest_triangles", s.finest_triangles},
       {"base_triangles", s.base_triangles},
       {"err0", s.err0},
       {"err_final", s.err_final}};
}

void to_json(json& j, const WriteReport& w) {
  j = {{"pages", w.pages},
       {"rtree_nodes", w.rtree_nodes},
       {"page_bytes", w.page_bytes},
       {"locator_bytes", w.locator_bytes},
       {"rtree_bytes", w.rtree_bytes},
       {"file_bytes", w.file_bytes},
       {"z_quantum", w.grid.step.z},
       {"z_shift", w.z_shift},
       {"dag_depth", w.dag_depth},
       {"write_seconds", w.seconds},
       {"write_phases_seconds",
        {{"sweep", w.seconds_sweep}, {"tables", w.seconds_tables}, {"commit", w.seconds_commit}}}};
}

void to_json(json& j, const ExtractStats& s) {
  j = {{"x", s.x},
       {"x_plus", s.x_plus},
       {"ops_visited", s.ops_visited},
       {"triangles", s.triangles},
       {"void_triangles", s.void_triangles},
       {"fans", s.fans},
       {"triangles_per_fan", s.triangles_per_fan()},
       {"starting_points", s.starting_points},
       {"domain_tests", s.domain_tests},
       {"held_ops_peak", s.held_ops_peak},
       {"held_bytes_peak", s.held_bytes_peak},
       {"extract_seconds", s.extract_seconds},
       {"expand_seconds", s.expand_seconds}};
}

void to_json(json& j, const SelectiveStats& s) {
  j = {{"evaluated", s.evaluated},
       {"selected", s.selected},
       {"splits", s.splits},
       {"degenerate_cases", s.degenerate_cases},
       {"forced_splits", s.forced_splits},
       {"ops_read", s.ops_read},
       {"vertices", s.vertices},
       {"triangles", s.triangles},
       {"flipped_triangles", s.flipped_triangles},
       {"displacement_bound", s.displacement_bound},
       {"seconds", s.seconds}};
}

void to_json(json& j, const SelectiveIndex::Stats& s) {
  j = {{"splits", s.splits},
       {"roots", s.roots},
       {"spawned_components", s.spawned_components},
       {"max_depth", s.max_depth},
       {"seconds", s.seconds}};
}

void to_json(json& j, const FrameStats& s) {
  const std::uint64_t morphs = s.coarsenings + s.refinings;
  j = {{"complete", s.complete},
       {"stop_resolution", s.stop_resolution},
       {"pending_coarsenings", s.pending_coarsenings},
       {"pending_refinings", s.pending_refinings},
       {"coarsenings", s.coarsenings},
       {"refinings", s.refinings},
       {"unreached_coarsenings", s.unreached_coarsenings},
       {"local_morphs", morphs},
       {"local_morphs_pct", s.x == 0 ? 0.0 : 100.0 * double(morphs) / double(s.x)},
       {"morph_groups", s.morph_groups},
       {"morph_triangles", s.morph_triangles},
       {"morph_vertices", s.morph_vertices},
       {"triangles", s.triangles},
       {"triangles_in", s.triangles_in},
       {"triangles_out", s.triangles_out},
       {"x", s.x},
       {"ops_tested", s.ops_tested},
       {"verdicts_kept", s.verdicts_kept},
       {"traversed", s.traversed},
       {"update_ms", 1000.0 * s.seconds},
       {"coarsen_ms", 1000.0 * s.coarsen_seconds},
       {"refine_ms", 1000.0 * s.refine_seconds},
       {"morph_ms", 1000.0 * s.morph_seconds}};
}

void to_json(json& j, const DatabaseStats& s) {
  j = {{"pages_read", s.pages_read},
       {"pages_prefetched", s.pages_prefetched},
       {"page_bytes_read", s.page_bytes_read},
       {"rtree_nodes_read", s.rtree_nodes_read},
       {"rtree_bytes_read", s.rtree_bytes_read},
       {"locator_bytes_read", s.locator_bytes_read},
       {"lmdb_bytes_read", s.lmdb_bytes_read},
       {"cache_hits", s.cache.hits},
       {"cache_misses", s.cache.misses},
       {"cache_evictions", s.cache.evictions},
       {"cache_peak_bytes", s.cache.peak_held_bytes},
       {"bytes_decoded", s.cache.bytes_decoded}};
}

void to_json(json& j, const VerifyReport& r) {
  j = {{"ok", r.ok()}, {"faults", r.faults},       {"pages", r.pages},
       {"ops", r.ops}, {"triangles", r.triangles}, {"links", r.links}};
}

namespace tools {

nlohmann::json ingest_json(const IngestReport& r, const std::string& input,
                           const std::string& db_path, const IngestOptions& options) {
  json report;
  json& in = report["input"];
  std::visit(
      [&](const auto& part) {
        using Part = std::decay_t<decltype(part)>;
        if constexpr (std::is_same_v<Part, QemPmReport>) {
          in = part.input;
          in["kind"] = "mesh";
          in["read_seconds"] = part.read_seconds;
          report["simplification"] = part.stats;
        } else if constexpr (std::is_same_v<Part, BlockPmReport>) {
          in = {{"kind", "mesh"},
                {"vertices", part.stats.vertices},
                {"triangles", part.stats.triangles}};
          json& blocks = report["blocks"] = part.stats;
          blocks["triangles_per_second"] =
              double(part.stats.triangles) / std::max(1e-9, r.build_seconds);
          blocks["temp_bytes"] = r.temp_bytes;
        } else if constexpr (std::is_same_v<Part, GreedyTinReport>) {
          in = part;
          in["kind"] = "terrain";
        } else {
          in = part;
          in["kind"] = "terrain";
          json& blocks = report["blocks"] = part.stats;
          blocks["block_cells"] = options.block_cells;
          blocks["temp_bytes"] = r.temp_bytes;
        }
      },
      r.build);
  in["path"] = input;
  report["crmr"] = r.crmr;
  report["crmr"]["build_seconds"] = r.build_seconds;
  json& db = report["database"] = r.database;
  db["path"] = db_path;
  db["codec"] = std::string(storage::codec_name(options.codec));
  db["bytes_per_vertex"] =
      double(r.database.file_bytes) / double(std::max<std::uint64_t>(1, r.crmr.vertices));
  return report;
}

void print_report(const nlohmann::json& report, bool json) {
  if (json) std::cout << report.dump(2) << "\n";
}

}  // namespace tools
}  // namespace smr
