#include "smr/rcf/spec.h"

#include <cmath>
#include <memory>
#include <string>

#include "base/error.h"

namespace smr {

namespace {
void check_level(double v, const std::string& option) {
  if (!(v >= 0.0 && v <= 1.0))
    throw_input(option + ": resolution level must be in [0, 1], got " + std::to_string(v));
}
void check_aoi(const AoiSpec& a, const std::string& option) {
  if (!std::isfinite(a.x) || !std::isfinite(a.y)) throw_input(option + ": centre must be finite");
  if (!(a.radius > 0.0) || !std::isfinite(a.radius)) {
    throw_input(option + ": radius must be a positive number, got " + std::to_string(a.radius));
  }
  check_level(a.level, option);
}
Rcf build_rcf(const RcfSpec& spec, ModelKind kind, const Heightfield* dem,
              const MetricFrame& frame) {
  validate(spec);
  if (kind == ModelKind::kMesh3d) {
    const char* flat = !spec.aois.empty()    ? "--aoi"
                       : !spec.discs.empty() ? "--disc"
                       : spec.frustum_level  ? "--frustum-level"
                       : spec.centre_cone    ? "--centre-cone"
                       : spec.critical_level ? "--critical-lines"
                                             : nullptr;
    if (flat != nullptr) {
      throw_input(std::string(flat) +
                  " is a 2.5-D (terrain) criterion; for a 3-D mesh use --volume or --ball "
                  "x,y,z,radius,level");
    }
  }
  Rcf rcf;
  if (spec.camera && spec.cull) {
    rcf.add(std::make_shared<FrustumCulling>(*spec.camera, frame));
    if (frame.identity()) rcf.add(std::make_shared<BackfaceCulling>(*spec.camera));
  }
  // The camera's footprint terms, made in the metric frame and asked there.
  const auto camera_term = [&](WedgeTerm term) -> std::shared_ptr<const ObjectSpaceTerm> {
    auto t = std::make_shared<WedgeTerm>(std::move(term));
    if (frame.identity()) return t;
    return std::make_shared<FramedTerm>(std::move(t), frame);
  };
  const Camera metric_camera = spec.camera ? frame.apply(*spec.camera) : Camera{};
  ObjectSpaceFunction g;
  if (spec.floor) g.add(std::make_shared<ConstantTerm>(*spec.floor));
  for (const AoiSpec& a : spec.aois)
    g.add(std::make_shared<GaussianTerm>(Vec2{a.x, a.y}, a.radius, a.level));
  for (const AoiSpec& a : spec.discs)
    g.add(std::make_shared<DiscTerm>(Vec2{a.x, a.y}, a.radius, a.level));
  if (spec.frustum_level) {
    g.add(camera_term(WedgeTerm::frustum_footprint(metric_camera, *spec.frustum_level)));
  }
  if (spec.centre_cone) {
    g.add(camera_term(
        WedgeTerm::centre_cone(metric_camera, spec.centre_cone->first, spec.centre_cone->second)));
  }
  if (spec.critical_level) {
    if (dem == nullptr) throw_input("--critical-lines needs the source DEM");
    auto lines =
        std::make_shared<CriticalLines>(CriticalLines::detect(*dem, {spec.critical_relief}));
    g.add(std::make_shared<CriticalLineTerm>(lines, *spec.critical_level));
  }
  if (!spec.volumes.empty()) {
    std::vector<Volume> volumes;
    for (const VolumeSpec& v : spec.volumes)
      volumes.push_back({Vec3{v.x, v.y, v.z}, v.radius, v.level, v.gaussian});
    rcf.add(std::make_shared<VolumeCriterion>(std::move(volumes)));
  }
  if (!spec.has_similarity()) g.add(std::make_shared<ConstantTerm>(1.0));
  if (!g.empty()) rcf.add(std::make_shared<ObjectSpaceCriterion>(std::move(g)));
  if (spec.pixel_error) {
    rcf.add(std::make_shared<ScreenSpaceCriterion>(*spec.camera, *spec.pixel_error, spec.screen_aoi,
                                                   kind == ModelKind::kTerrain, frame));
  }
  return rcf;
}
}  // namespace

bool RcfSpec::has_similarity() const {
  return pixel_error || floor || !aois.empty() || !discs.empty() || frustum_level || centre_cone ||
         critical_level || !volumes.empty();
}

void validate(const RcfSpec& s) {
  if (s.camera) s.camera->validate();
  if (s.pixel_error) {
    if (!s.camera) throw_input("--pixel-error needs a camera (--eye and --target)");
    if (!(*s.pixel_error > 0.0) || !std::isfinite(*s.pixel_error)) {
      throw_input("--pixel-error must be a positive number of pixels, got " +
                  std::to_string(*s.pixel_error));
    }
  }
  if (s.screen_aoi) {
    if (!s.pixel_error) throw_input("--screen-aoi needs --pixel-error");
    if (!(s.screen_aoi->radius_px > 0.0) || !(s.screen_aoi->pixel_error > 0.0) ||
        !std::isfinite(s.screen_aoi->center_px.x) || !std::isfinite(s.screen_aoi->center_px.y)) {
      throw_input("--screen-aoi u,v,radius_px,pixel_error needs a positive radius and pixel error");
    }
  }
  if (s.floor) check_level(*s.floor, "--floor");
  for (const AoiSpec& a : s.aois) check_aoi(a, "--aoi");
  for (const AoiSpec& a : s.discs) check_aoi(a, "--disc");
  for (const VolumeSpec& v : s.volumes) {
    const std::string option = v.gaussian ? "--volume" : "--ball";
    if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z))
      throw_input(option + ": centre must be finite");
    if (!(v.radius > 0.0) || !std::isfinite(v.radius)) {
      throw_input(option + ": radius must be a positive number, got " + std::to_string(v.radius));
    }
    check_level(v.level, option);
  }
  if (s.frustum_level) {
    if (!s.camera) throw_input("--frustum-level needs a camera (--eye and --target)");
    check_level(*s.frustum_level, "--frustum-level");
  }
  if (s.centre_cone) {
    if (!s.camera) throw_input("--centre-cone needs a camera (--eye and --target)");
    if (!(s.centre_cone->first > 0.0 && s.centre_cone->first < 89.0)) {
      throw_input("--centre-cone: half-angle must be in (0, 89) degrees");
    }
    check_level(s.centre_cone->second, "--centre-cone");
  }
  if (s.critical_level) check_level(*s.critical_level, "--critical-lines");
  if (!(s.critical_relief >= 0.0) || !std::isfinite(s.critical_relief)) {
    throw_input("--critical-relief must be >= 0");
  }
}

Rcf make_rcf(const RcfSpec& spec, ModelKind kind, const Heightfield* dem) {
  return build_rcf(spec, kind, dem, MetricFrame{});
}

Rcf make_rcf(const RcfSpec& spec, const CrmrInfo& info, const Heightfield* dem) {
  const MetricFrame frame =
      info.kind == ModelKind::kTerrain ? MetricFrame::of(info.georef, info.bounds) : MetricFrame{};
  return build_rcf(spec, info.kind, dem, frame);
}

}  // namespace smr
