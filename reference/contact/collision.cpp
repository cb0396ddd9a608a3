/// \file collision.cpp
/// Collision detection (§3.2.4): broad phase on grown world bounding boxes, narrow phase by
/// surface samples against signed distances (spheres exactly), contact reduction per pair.

#include "reference/contact/collision.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "reference/core/parallel.hpp"

namespace monolith {

namespace {

/// Samples of a body against a sphere count only where they face the sphere's centre within
/// this cosine (about 8 degrees).
constexpr double kSphereSampleCosine = 0.99;

template <int Dim>
bool boxes_overlap(const Box<Dim>& a, const Box<Dim>& b) {
  return (a.min().array() <= b.max().array()).all() && (b.min().array() <= a.max().array()).all();
}

template <int Dim>
Box<Dim> grown(Box<Dim> b, double by) {
  b.min().array() -= by;
  b.max().array() += by;
  return b;
}

/// Lexicographic "a before b" with a tolerance per coordinate (ties within tol fall through to
/// the next axis): stable under rounding of equal geometry computed two ways.
template <int Dim>
bool lex_before(const Vec<Dim>& a, const Vec<Dim>& b, double tol) {
  for (int k = 0; k < Dim; ++k) {
    if (a[k] < b[k] - tol) return true;
    if (a[k] > b[k] + tol) return false;
  }
  return false;
}

/// Index of the member maximising score; scores within score_tol of the best are ties, broken
/// by the smaller gap phi, then by the lexicographically first midpoint (coordinates within
/// tol are equal); -1 if empty.
template <int Dim, class Score>
int argmax_geometric(const std::vector<int>& members, const std::vector<Contact<Dim>>& c,
                     const std::vector<Vec<Dim>>& mids, double score_tol, double tol,
                     Score score) {
  int best = -1;
  double best_score = 0.0;
  for (int m : members) {
    const double s = score(m);
    bool better = best < 0 || s > best_score + score_tol;
    if (!better && s >= best_score - score_tol) {
      if (c[m].phi < c[best].phi - tol) better = true;
      else if (c[m].phi <= c[best].phi + tol) better = lex_before<Dim>(mids[m], mids[best], tol);
    }
    if (better) {
      best = m;
      best_score = s;
    }
  }
  return best;
}

/// Signed area of (p1, p2, p) in the plane normal to n (3D); the 2D version is unused.
inline double plane_area(const Vec<3>& p1, const Vec<3>& p2, const Vec<3>& p, const Vec<3>& n) {
  return (p2 - p1).cross(p - p1).dot(n);
}

/// Selects the extreme points of one patch (indices into candidates).
template <int Dim>
std::vector<int> patch_extremes(const std::vector<Contact<Dim>>& c, const std::vector<int>& members,
                                int max_points) {
  if (static_cast<int>(members.size()) <= max_points) return members;
  // geometry on the midpoints between the two surfaces (invariant under swapping a and b)
  std::vector<Vec<Dim>> mids(c.size());
  Box<Dim> box;
  double min_phi = c[members.front()].phi;
  for (int m : members) {
    mids[m] = c[m].point + 0.5 * c[m].phi * c[m].normal;
    box.extend(mids[m]);
    min_phi = std::min(min_phi, c[m].phi);
  }
  const double scale = box.sizes().norm();
  const double tol = 1e-7 * scale + 1e-14;
  // the patch normal (mean of the members') and distances in its tangent plane
  Vec<Dim> n = Vec<Dim>::Zero();
  for (int m : members) n += c[m].normal;
  if (n.norm() == 0.0) n = c[members.front()].normal;
  n.normalize();
  auto tangent_distance = [&](const Vec<Dim>& x, const Vec<Dim>& y) {
    const Vec<Dim> d = x - y;
    return (d - d.dot(n) * n).norm();
  };
  Vec<Dim> centroid = Vec<Dim>::Zero();
  for (int m : members) centroid += mids[m];
  centroid /= static_cast<double>(members.size());
  // p1: the deepest point (ties: the one farthest from the patch centroid)
  std::vector<int> deepest;
  for (int m : members) {
    if (c[m].phi <= min_phi + tol) deepest.push_back(m);
  }
  const int p1 = argmax_geometric<Dim>(deepest, c, mids, tol, tol,
                                       [&](int m) { return tangent_distance(mids[m], centroid); });
  std::vector<int> keep{p1};
  if (max_points < 2) return keep;
  // p2: the farthest from p1
  const int p2 = argmax_geometric<Dim>(members, c, mids, tol, tol,
                                       [&](int m) { return tangent_distance(mids[m], mids[p1]); });
  const double span = tangent_distance(mids[p2], mids[p1]);
  if (!(span > 10.0 * tol)) return keep;
  keep.push_back(p2);
  if constexpr (Dim == 3) {
    if (max_points < 3) return keep;
    // p3: the largest triangle area with p1 p2 in the patch plane; p4: the largest on the
    // other side of the line p1 p2
    const double area_tol = 1e-3 * span * span;
    auto area = [&](int m) { return plane_area(mids[p1], mids[p2], mids[m], n); };
    const int p3 = argmax_geometric<3>(members, c, mids, tol * span, tol,
                                       [&](int m) { return std::abs(area(m)); });
    if (!(std::abs(area(p3)) > area_tol)) return keep;
    keep.push_back(p3);
    if (max_points < 4) return keep;
    const double side = area(p3) > 0.0 ? -1.0 : 1.0;
    const int p4 = argmax_geometric<3>(members, c, mids, tol * span, tol,
                                       [&](int m) { return side * area(m); });
    if (side * area(p4) > area_tol) keep.push_back(p4);
  }
  return keep;
}

}  // namespace

// --- walls ---------------------------------------------------------------------------------------

template <int Dim>
Walls<Dim> Walls<Dim>::from_scene(const SceneDesc& scene) {
  Walls w;
  for (int a = 0; a < Dim; ++a) {
    w.lower[a] = scene.domain.lower[a];
    w.upper[a] = scene.domain.upper[a];
  }
  for (int f = 0; f < 2 * Dim; ++f) w.is_wall[f] = scene.domain.boundary[f] == BoundaryType::wall;
  w.friction = scene.domain.wall_friction;
  w.restitution = scene.domain.wall_restitution;
  return w;
}

template <int Dim>
Vec<Dim> Walls<Dim>::face_normal(int face) {
  Vec<Dim> n = Vec<Dim>::Zero();
  n[face / 2] = face % 2 == 0 ? 1.0 : -1.0;
  return n;
}

template <int Dim>
double Walls<Dim>::face_distance(int face, const Vec<Dim>& x) const {
  const int a = face / 2;
  return face % 2 == 0 ? x[a] - lower[a] : upper[a] - x[a];
}

// --- reduction -----------------------------------------------------------------------------------

template <int Dim>
std::vector<Contact<Dim>> reduce_contacts(std::vector<Contact<Dim>> cand,
                                          const ContactReduction& reduction) {
  if (cand.size() <= 1) return cand;
  // deepest first; exact ties by midpoint coordinates (deterministic)
  std::vector<int> order(cand.size());
  std::iota(order.begin(), order.end(), 0);
  std::vector<Vec<Dim>> mids(cand.size());
  for (std::size_t i = 0; i < cand.size(); ++i) mids[i] = cand[i].point + 0.5 * cand[i].phi * cand[i].normal;
  std::sort(order.begin(), order.end(), [&](int l, int r) {
    if (cand[l].phi != cand[r].phi) return cand[l].phi < cand[r].phi;
    for (int k = 0; k < Dim; ++k) {
      if (mids[l][k] != mids[r][k]) return mids[l][k] < mids[r][k];
    }
    return l < r;
  });
  // greedy clustering by normal: a candidate joins the first patch whose first (deepest)
  // normal is within the cone
  std::vector<std::vector<int>> patches;
  for (int i : order) {
    bool placed = false;
    for (auto& p : patches) {
      if (cand[p.front()].normal.dot(cand[i].normal) >= reduction.cluster_cosine) {
        p.push_back(i);
        placed = true;
        break;
      }
    }
    if (!placed) patches.push_back({i});
  }
  // larger patches first (stable: ties keep their depth order)
  std::stable_sort(patches.begin(), patches.end(),
                   [](const std::vector<int>& l, const std::vector<int>& r) { return l.size() > r.size(); });
  const int max_points = Dim == 2 ? reduction.max_points_2d : reduction.max_points_3d;
  std::vector<Contact<Dim>> out;
  std::vector<Vec<Dim>> kept;
  for (const auto& p : patches) {
    const std::size_t before = kept.size();
    for (int k : patch_extremes<Dim>(cand, p, max_points)) {
      // drop a point that a larger patch already has (within merge_distance)
      bool duplicate = false;
      for (std::size_t i = 0; i < before && !duplicate; ++i) {
        duplicate = (kept[i] - mids[k]).norm() <= reduction.merge_distance;
      }
      if (duplicate) continue;
      out.push_back(cand[k]);
      kept.push_back(mids[k]);
    }
  }
  return out;
}

// --- detection -----------------------------------------------------------------------------------

namespace {

/// The broad phase: every body's world box grown by the search distance, the pairs (i < j) with
/// at least one dynamic body whose boxes overlap, and the world positions of the surface samples
/// of every body that takes part (pairs and walls; none for spheres, which are exact).
template <int Dim>
struct BroadPhase {
  std::vector<Box<Dim>> boxes;
  std::vector<std::pair<int, int>> pairs;
  std::vector<std::vector<Vec<Dim>>> world;
};

/// What the narrow phase of every pair reads: the bodies, the broad phase, the search distance
/// and the reduction settings.
template <int Dim>
struct PairQuery {
  const std::vector<RigidBody<Dim>>& bodies;
  const BroadPhase<Dim>& bp;
  double search_distance;
  const ContactReduction& reduction;
};

template <int Dim>
BroadPhase<Dim> broad_phase(const std::vector<RigidBody<Dim>>& bodies, double search_distance) {
  const int n = static_cast<int>(bodies.size());
  BroadPhase<Dim> bp;
  bp.boxes.resize(n);
  for (int i = 0; i < n; ++i) bp.boxes[i] = grown<Dim>(bodies[i].bounds(), search_distance);
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      if (!bodies[i].is_dynamic() && !bodies[j].is_dynamic()) continue;
      if (boxes_overlap<Dim>(bp.boxes[i], bp.boxes[j])) bp.pairs.emplace_back(i, j);
    }
  }
  std::vector<char> needed(n, 0);
  for (const auto& p : bp.pairs) needed[p.first] = needed[p.second] = 1;
  for (int i = 0; i < n; ++i) needed[i] = needed[i] || bodies[i].is_dynamic();
  bp.world.resize(n);
#pragma omp parallel for schedule(dynamic) num_threads(process_threads())
  for (int i = 0; i < n; ++i) {
    if (!needed[i] || bodies[i].is_sphere()) continue;
    const Mat<Dim> r = bodies[i].rotation();
    const Vec<Dim> shift = bodies[i].position - r * bodies[i].rest_center_of_mass();
    bp.world[i].reserve(bodies[i].surface_samples().size());
    for (const auto& x : bodies[i].surface_samples()) bp.world[i].push_back(r * x + shift);
  }
  return bp;
}

/// A candidate's normal, as an outward direction of the sampled body, must fit its cone.
template <int Dim>
bool fits_cone(const ContactReduction& reduction, const RigidBody<Dim>& body, const Vec<Dim>& x,
               const Vec<Dim>& outward) {
  const double needed = body.is_box() ? reduction.box_cone_cosine : reduction.accept_cosine;
  return body.normal_cone_cosine(x, outward) >= needed;
}

/// The contact normal (out of q, towards p) for a sample x of p with gap phi to q: the SDF
/// gradient of q, or, when that comes from an edge or corner of a box q and x lies inside a face
/// of a box p, that face's normal (the normal of a face-edge contact is the face's: the gradient
/// near the edge fans out); false if the normal does not fit p's cone.
template <int Dim>
bool sample_normal(const ContactReduction& reduction, const RigidBody<Dim>& p,
                   const RigidBody<Dim>& q, const Vec<Dim>& x, double phi, Vec<Dim>* normal) {
  const Vec<Dim> g = q.gradient(x);
  if (!fits_cone<Dim>(reduction, p, x, Vec<Dim>(-g))) return false;
  Vec<Dim> face, q_face;
  if (q.is_box() && !q.box_face_normal(Vec<Dim>(x - phi * g), &q_face) &&
      p.box_face_normal(x, &face)) {
    *normal = -face;
  } else {
    *normal = g;
  }
  return true;
}

/// Two spheres: at most one exact contact from the centre distance.
template <int Dim>
std::vector<Contact<Dim>> sphere_sphere_contacts(const Contact<Dim>& proto, const RigidBody<Dim>& ba,
                                                 const RigidBody<Dim>& bb, double search_distance) {
  std::vector<Contact<Dim>> cand;
  // (periodic axes: the image of a's centre nearest b's, RigidBody::set_periodic)
  const Vec<Dim> d = bb.nearest_image(ba.position) - bb.position;
  const double len = d.norm();
  const double phi = len - ba.sphere_radius() - bb.sphere_radius();
  if (phi < search_distance) {
    Contact<Dim> c = proto;
    c.normal = len > 0.0 ? Vec<Dim>(d / len) : Vec<Dim>(Vec<Dim>::UnitY());
    c.point = bb.position + bb.sphere_radius() * c.normal;
    c.phi = phi;
    cand.push_back(c);
  }
  return cand;
}

/// A sphere against any shape: the point of the other surface nearest the centre (exact for an
/// exact SDF), plus the other body's samples against the sphere's exact SDF so that a concave
/// shape touched in two places (a groove, a bowl's rim) gives both; each patch keeps only its
/// deepest point. a, b as in the pair (a dynamic); one of them is the sphere.
template <int Dim>
std::vector<Contact<Dim>> sphere_shape_contacts(const PairQuery<Dim>& in, const Contact<Dim>& proto,
                                                int a, int b) {
  const RigidBody<Dim>& ba = in.bodies[a];
  const RigidBody<Dim>& bb = in.bodies[b];
  std::vector<Contact<Dim>> cand;
  const bool a_round = ba.is_sphere();
  const int other_index = a_round ? b : a;
  const RigidBody<Dim>& round = a_round ? ba : bb;
  const RigidBody<Dim>& other = a_round ? bb : ba;
  const double radius = round.sphere_radius();
  // orient a contact given the unit direction g out of `other` towards the sphere, the point q
  // on other's surface and the gap
  auto add = [&](const Vec<Dim>& g, const Vec<Dim>& q, double phi) {
    Contact<Dim> c = proto;
    c.phi = phi;
    if (a_round) {
      c.normal = g;
      c.point = q;
    } else {
      c.normal = -g;
      c.point = q + phi * g;  // on the sphere
    }
    cand.push_back(c);
  };
  const double d = other.distance(round.position);
  if (d - radius < in.search_distance) {
    const Vec<Dim> g = other.gradient(round.position);
    add(g, Vec<Dim>(round.position - d * g), d - radius);
  }
  // the sphere's centre as other's samples see it (periodic axes: its image nearest other,
  // RigidBody::set_periodic; round.position itself otherwise)
  const Vec<Dim> centre = other.nearest_image(round.position);
  for (const auto& x : in.bp.world[other_index]) {
    if (!in.bp.boxes[a_round ? a : b].contains(x)) continue;
    const Vec<Dim> r = centre - x;
    const double len = r.norm();
    if (!(len - radius < in.search_distance) || len == 0.0) continue;
    // the sample must face the centre (within ~8 degrees)
    const Vec<Dim> towards = r / len;
    if (other.normal_cone_cosine(x, towards) < kSphereSampleCosine) continue;
    Vec<Dim> face;
    if (other.is_box() && !other.box_face_normal(x, &face)) {
      // an edge or corner sample: the exact gap from that point
      add(towards, x, len - radius);
    } else {
      // a face (or smooth) sample: the touching point of the tangent plane at x, exact for a
      // flat face wherever the sample lies on it
      const Vec<Dim> n = other.is_box() ? face : other.gradient(x);
      const double height = n.dot(r);
      add(n, Vec<Dim>(centre - height * n), height - radius);
    }
  }
  ContactReduction sphere_reduction = in.reduction;
  sphere_reduction.max_points_2d = sphere_reduction.max_points_3d = 1;
  if (!(sphere_reduction.merge_distance > 0.0)) {
    sphere_reduction.merge_distance = std::max(other.sample_spacing(), 0.25 * radius);
  }
  return reduce_contacts<Dim>(std::move(cand), sphere_reduction);
}

/// The samples of body p (world positions, inside q's grown box `q_box`) within the search
/// distance of q's SDF, appended to `cand`. p = a (p_is_a): normal = grad d_q, the point on q =
/// x - phi n; p = b: normal = -grad d_q (the normal points from b to a), the point is the sample.
template <int Dim>
void add_sample_contacts(const Contact<Dim>& proto, const RigidBody<Dim>& p, const RigidBody<Dim>& q,
                         const std::vector<Vec<Dim>>& world, const Box<Dim>& q_box, bool p_is_a,
                         double search_distance, const ContactReduction& reduction,
                         std::vector<Contact<Dim>>& cand) {
  for (const auto& x : world) {
    if (!q_box.contains(x)) continue;
    const double phi = q.distance(x);
    if (!(phi < search_distance)) continue;
    Vec<Dim> normal;
    if (!sample_normal<Dim>(reduction, p, q, x, phi, &normal)) continue;
    Contact<Dim> c = proto;
    c.phi = phi;
    if (p_is_a) {
      c.normal = normal;
      c.point = x - phi * c.normal;
    } else {
      c.normal = -normal;
      c.point = x;
    }
    cand.push_back(c);
  }
}

/// Two sampled shapes: the samples of a against the SDF of b and those of b against the SDF of
/// a (add_sample_contacts), reduced.
template <int Dim>
std::vector<Contact<Dim>> sampled_pair_contacts(const PairQuery<Dim>& in, const Contact<Dim>& proto,
                                                int a, int b) {
  const RigidBody<Dim>& ba = in.bodies[a];
  const RigidBody<Dim>& bb = in.bodies[b];
  std::vector<Contact<Dim>> cand;
  add_sample_contacts<Dim>(proto, ba, bb, in.bp.world[a], in.bp.boxes[b], true, in.search_distance,
                           in.reduction, cand);
  add_sample_contacts<Dim>(proto, bb, ba, in.bp.world[b], in.bp.boxes[a], false, in.search_distance,
                           in.reduction, cand);
  ContactReduction pair_reduction = in.reduction;
  if (!(pair_reduction.merge_distance > 0.0)) {
    pair_reduction.merge_distance = 0.5 * std::max(ba.sample_spacing(), bb.sample_spacing());
  }
  return reduce_contacts<Dim>(std::move(cand), pair_reduction);
}

/// The narrow phase of one broad-phase pair: body_a is the dynamic body (the lower index if
/// both are), friction sqrt(mu_a mu_b) and restitution max(e_a, e_b) of the pair.
template <int Dim>
std::vector<Contact<Dim>> narrow_phase(const PairQuery<Dim>& in, std::pair<int, int> pair) {
  int a = pair.first, b = pair.second;
  if (!in.bodies[a].is_dynamic()) std::swap(a, b);
  const RigidBody<Dim>& ba = in.bodies[a];
  const RigidBody<Dim>& bb = in.bodies[b];
  Contact<Dim> proto;
  proto.body_a = a;
  proto.body_b = b;
  proto.friction = std::sqrt(ba.friction * bb.friction);
  proto.restitution = std::max(ba.restitution, bb.restitution);
  if (ba.is_sphere() && bb.is_sphere())
    return sphere_sphere_contacts<Dim>(proto, ba, bb, in.search_distance);
  if (ba.is_sphere() || bb.is_sphere()) return sphere_shape_contacts<Dim>(in, proto, a, b);
  return sampled_pair_contacts<Dim>(in, proto, a, b);
}

/// A dynamic body against the domain's wall faces: per face whose plane the grown box reaches,
/// a sphere's exact contact or the body's samples within the search distance (reduced); a wall
/// counts as a body with the domain's coefficients.
template <int Dim>
std::vector<Contact<Dim>> wall_contacts(const RigidBody<Dim>& body, int index, const Box<Dim>& box,
                                        const std::vector<Vec<Dim>>& world, const Walls<Dim>& walls,
                                        double search_distance, const ContactReduction& reduction) {
  std::vector<Contact<Dim>> out;
  for (int f = 0; f < 2 * Dim; ++f) {
    if (!walls.is_wall[f]) continue;
    // reject by the grown box's nearest extent
    const int axis = f / 2;
    const double gap = f % 2 == 0 ? box.min()[axis] - walls.lower[axis]
                                  : walls.upper[axis] - box.max()[axis];
    if (gap > 0.0) continue;
    Contact<Dim> proto;
    proto.body_a = index;
    proto.body_b = -1;
    proto.wall_face = f;
    proto.normal = Walls<Dim>::face_normal(f);
    proto.friction = std::sqrt(body.friction * walls.friction);
    proto.restitution = std::max(body.restitution, walls.restitution);
    std::vector<Contact<Dim>> cand;
    if (body.is_sphere()) {
      // exact: the centre's distance to the plane minus the radius
      const double d = walls.face_distance(f, body.position);
      if (d - body.sphere_radius() < search_distance) {
        Contact<Dim> c = proto;
        c.phi = d - body.sphere_radius();
        c.point = body.position - d * c.normal;
        cand.push_back(c);
      }
    } else {
      for (const auto& x : world) {
        const double phi = walls.face_distance(f, x);
        if (!(phi < search_distance)) continue;
        if (!fits_cone<Dim>(reduction, body, x, Vec<Dim>(-proto.normal))) continue;
        Contact<Dim> c = proto;
        c.phi = phi;
        c.point = x - phi * c.normal;
        cand.push_back(c);
      }
      ContactReduction wall_reduction = reduction;
      if (!(wall_reduction.merge_distance > 0.0)) wall_reduction.merge_distance = 0.5 * body.sample_spacing();
      cand = reduce_contacts<Dim>(std::move(cand), wall_reduction);
    }
    out.insert(out.end(), cand.begin(), cand.end());
  }
  return out;
}

}  // namespace

template <int Dim>
std::vector<Contact<Dim>> detect_contacts(const std::vector<RigidBody<Dim>>& bodies,
                                          const Walls<Dim>& walls, double search_distance,
                                          const ContactReduction& reduction) {
  const int n = static_cast<int>(bodies.size());
  const BroadPhase<Dim> bp = broad_phase<Dim>(bodies, search_distance);
  const PairQuery<Dim> query{bodies, bp, search_distance, reduction};
  // narrow phase per pair, then the dynamic bodies against the walls, each in parallel
  std::vector<std::vector<Contact<Dim>>> pair_contacts(bp.pairs.size());
#pragma omp parallel for schedule(dynamic) num_threads(process_threads())
  for (std::size_t k = 0; k < bp.pairs.size(); ++k)
    pair_contacts[k] = narrow_phase<Dim>(query, bp.pairs[k]);
  std::vector<std::vector<Contact<Dim>>> body_wall_contacts(n);
#pragma omp parallel for schedule(dynamic) num_threads(process_threads())
  for (int i = 0; i < n; ++i)
    if (bodies[i].is_dynamic())
      body_wall_contacts[i] = wall_contacts<Dim>(bodies[i], i, bp.boxes[i], bp.world[i], walls,
                                                 search_distance, reduction);
  // in a fixed order whatever the threads: the pairs', then the walls'
  std::vector<Contact<Dim>> out;
  for (auto& v : pair_contacts) out.insert(out.end(), v.begin(), v.end());
  for (auto& v : body_wall_contacts) out.insert(out.end(), v.begin(), v.end());
  return out;
}

template struct Walls<2>;
template struct Walls<3>;
template std::vector<Contact<2>> reduce_contacts<2>(std::vector<Contact<2>>, const ContactReduction&);
template std::vector<Contact<3>> reduce_contacts<3>(std::vector<Contact<3>>, const ContactReduction&);
template std::vector<Contact<2>> detect_contacts<2>(const std::vector<RigidBody<2>>&, const Walls<2>&,
                                                    double, const ContactReduction&);
template std::vector<Contact<3>> detect_contacts<3>(const std::vector<RigidBody<3>>&, const Walls<3>&,
                                                    double, const ContactReduction&);

}  // namespace monolith
