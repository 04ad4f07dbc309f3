// A user's description of an RCF (what the CLI's options fill in) and the factory that turns it
// into components. Defaults: with no similarity criterion at all, g = 1 everywhere (the finest
// mesh); a camera enables frustum and back-face culling unless `cull` is false.
#pragma once

#include <optional>
#include <utility>
#include <vector>

#include "smr/core/crmr.h"
#include "smr/rcf/rcf.h"

namespace smr {

struct AoiSpec {
  double x = 0, y = 0, radius = 0, level = 0;
};

/// A 3-D volume of significance (rcf.h Volume): a ball, Gaussian or thresholded.
struct VolumeSpec {
  double x = 0, y = 0, z = 0, radius = 0, level = 0;
  bool gaussian = true;
};

struct RcfSpec {
  std::optional<Camera> camera;
  bool cull = true;
  std::optional<double> pixel_error;    // screen-space tau (needs a camera)
  std::optional<ScreenAoi> screen_aoi;  // needs pixel_error
  std::optional<double> floor;          // constant object-space level
  std::vector<AoiSpec> aois;            // Gaussian areas of interest
  std::vector<AoiSpec> discs;           // thresholded discs
  std::vector<VolumeSpec> volumes;      // 3-D volumes of significance
  std::optional<double> frustum_level;  // object-space frustum footprint term (needs a camera)
  std::optional<std::pair<double, double>> centre_cone;  // degrees, level (needs a camera)
  std::optional<double> critical_level;                  // critical-line term (needs the DEM)
  double critical_relief = 0.0;

  bool has_similarity() const;
};

/// Throws smr::Error naming the offending option when a value is out of range or inconsistent.
void validate(const RcfSpec& spec);

/// Builds the RCF. `dem` is needed only for the critical-line term; `kind` selects the
/// screen-space error direction (vertical for terrain). For a 3-D mesh the 2.5-D terms over xy
/// (areas of interest, discs, frustum footprint, centre cone, critical lines) are kInvalidInput:
/// volumes of significance are their 3-D form.
/// The camera is in model coordinates and judged as metric data (identity MetricFrame).
Rcf make_rcf(const RcfSpec& spec, ModelKind kind, const Heightfield* dem);
/// The same for the model `info` describes: a geographic raster's camera criteria (frustum,
/// screen space, frustum footprint, centre cone) are judged in its metric frame
/// (MetricFrame::of), where a camera in degrees of longitude and latitude and metres of height
/// means what it says; back-face culling is then left out (normal cones in degrees and metres
/// bound nothing; not culling is always allowed).
Rcf make_rcf(const RcfSpec& spec, const CrmrInfo& info, const Heightfield* dem);

}  // namespace smr
