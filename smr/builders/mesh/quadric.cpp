// Garland & Heckbert 1997, sections 5 and 6.1: face and boundary-constraint quadrics.
#include "smr/builders/mesh/quadric.h"

#include <glm/geometric.hpp>

namespace smr::qem {

Quadric face_quadric(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = glm::cross(b - a, c - a);
  const double len = glm::length(n);
  Quadric q;
  if (len > 0.0) q.add_plane(n / len, -glm::dot(n / len, a), 0.5 * len);
  return q;
}

bool boundary_quadric(const Vec3& a, const Vec3& b, const Vec3& normal, double weight, Quadric& q) {
  const double len = glm::length(normal);
  if (!(len > 0.0)) return false;
  const Vec3 e = b - a;
  Vec3 m = glm::cross(e, normal / len);
  const double ml = glm::length(m);
  if (!(ml > 0.0)) return false;
  m /= ml;
  q.add_plane(m, -glm::dot(m, a), weight * glm::dot(e, e));
  return true;
}

}  // namespace smr::qem
