/// \file test_collision.cpp
/// Collision detection (§3.2.4): exact sphere contacts, resting face contacts reduced to the
/// corners, stacked boxes, edge contacts of rotated boxes, a mesh on a wall, the b -> a normal
/// convention, separated bodies, body-order symmetry and determinism, in 2D and 3D.

#include <catch2/catch.hpp>
#include <cmath>
#include <omp.h>

#include "reference/contact/collision.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/rigid/rigid_body.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using monolith::testing::as_std;
using monolith::testing::box_spec;
using Catch::Matchers::WithinAbs;
using Catch::Matchers::WithinRel;

namespace {

template <int Dim>
RigidBody<Dim> make_body(const ShapeSpec& shape, BodyMotion motion = BodyMotion::dynamic,
                         double spacing = 0.01, double friction = 0.5, double restitution = 0.0) {
  BodySpec spec;
  spec.name = enum_name(shape.type);
  spec.motion = motion;
  spec.shape = shape;
  spec.density = 500.0;
  spec.friction = friction;
  spec.restitution = restitution;
  ShapePtr<Dim> s = make_shape<Dim>(shape, "test");
  const auto props = mass_properties<Dim>(shape, *s, spec.density);
  return RigidBody<Dim>(spec, std::move(s), props, spacing);
}

template <int Dim>
ShapeSpec sphere(const Vec<Dim>& c, double r) {
  ShapeSpec s;
  s.type = ShapeType::sphere;
  s.center = as_std<Dim>(c);
  s.radius = r;
  return s;
}

/// The unit-cube domain with walls on every face.
template <int Dim>
Walls<Dim> unit_walls(double friction = 0.3, double restitution = 0.1) {
  Walls<Dim> w;
  w.lower = Vec<Dim>::Zero();
  w.upper = Vec<Dim>::Ones();
  w.is_wall.fill(true);
  w.friction = friction;
  w.restitution = restitution;
  return w;
}

/// Walls far away (no wall contacts).
template <int Dim>
Walls<Dim> no_walls() {
  Walls<Dim> w;
  w.lower = Vec<Dim>::Constant(-10);
  w.upper = Vec<Dim>::Constant(10);
  return w;
}

template <int Dim>
Vec<Dim> up() {
  return Vec<Dim>::Unit(1);
}

/// Checks that every corner of the bottom face of an axis-aligned box (centre c, half h) is
/// among the contact points (on the floor y = floor_y) and that there are no others.
template <int Dim>
void check_bottom_corners(const std::vector<Contact<Dim>>& contacts, const Vec<Dim>& c,
                          const Vec<Dim>& h, double floor_y) {
  REQUIRE(contacts.size() == (Dim == 2 ? 2u : 4u));
  for (int corner = 0; corner < (Dim == 2 ? 2 : 4); ++corner) {
    Vec<Dim> p = c;
    p[0] += (corner & 1 ? 1 : -1) * h[0];
    if constexpr (Dim == 3) p[2] += (corner & 2 ? 1 : -1) * h[2];
    p[1] = floor_y;
    int found = 0;
    for (const auto& k : contacts) found += (k.point - p).norm() < 1e-12;
    CHECK(found == 1);
  }
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("sphere-sphere: one exact contact, normal from b to a",
                       "[unit][collision]", ((int Dim), Dim), 2, 3) {
  Vec<Dim> ca = Vec<Dim>::Constant(0.5), cb = Vec<Dim>::Constant(0.5);
  Vec<Dim> dir = Vec<Dim>::Ones().normalized();
  ca += 0.105 * dir;
  cb -= 0.1 * dir;
  std::vector<RigidBody<Dim>> bodies{make_body<Dim>(sphere<Dim>(ca, 0.1), BodyMotion::dynamic, 0.01, 0.4),
                                     make_body<Dim>(sphere<Dim>(cb, 0.1), BodyMotion::dynamic, 0.01, 0.9, 0.6)};
  const auto c = detect_contacts<Dim>(bodies, no_walls<Dim>(), 0.01);
  REQUIRE(c.size() == 1);
  CHECK(c[0].body_a == 0);
  CHECK(c[0].body_b == 1);
  CHECK_THAT(c[0].phi, WithinAbs(0.005, 1e-14));
  CHECK((c[0].normal - dir).norm() < 1e-14);
  CHECK((c[0].point - (cb + 0.1 * dir)).norm() < 1e-14);
  CHECK((c[0].point_a() - (ca - 0.1 * dir)).norm() < 1e-14);
  CHECK_THAT(c[0].friction, WithinRel(std::sqrt(0.4 * 0.9), 1e-15));
  CHECK(c[0].restitution == 0.6);
  // penetrating: negative gap
  bodies[0].position -= 0.01 * dir;
  const auto p = detect_contacts<Dim>(bodies, no_walls<Dim>(), 0.01);
  REQUIRE(p.size() == 1);
  CHECK_THAT(p[0].phi, WithinAbs(-0.005, 1e-14));
  // beyond the search distance: none
  bodies[0].position += 0.03 * dir;
  CHECK(detect_contacts<Dim>(bodies, no_walls<Dim>(), 0.01).empty());
}

TEMPLATE_TEST_CASE_SIG("sphere-wall: exact contact from the centre distance", "[unit][collision]",
                       ((int Dim), Dim), 2, 3) {
  Vec<Dim> c = Vec<Dim>::Constant(0.5);
  c[1] = 0.102;
  std::vector<RigidBody<Dim>> bodies{make_body<Dim>(sphere<Dim>(c, 0.1))};
  const auto contacts = detect_contacts<Dim>(bodies, unit_walls<Dim>(), 0.01);
  REQUIRE(contacts.size() == 1);
  const auto& k = contacts[0];
  CHECK(k.body_a == 0);
  CHECK(k.body_b == -1);
  CHECK(k.wall_face == 2);
  CHECK_THAT(k.phi, WithinAbs(0.002, 1e-15));
  CHECK((k.normal - up<Dim>()).norm() == 0.0);
  Vec<Dim> foot = c;
  foot[1] = 0.0;
  CHECK((k.point - foot).norm() < 1e-15);
  // the wall counts as a body: sqrt(0.5 x 0.3), max(0, 0.1)
  CHECK_THAT(k.friction, WithinRel(std::sqrt(0.5 * 0.3), 1e-15));
  CHECK(k.restitution == 0.1);
}

TEMPLATE_TEST_CASE_SIG("box resting on the floor: the face contact reduces to the corners",
                       "[unit][collision]", ((int Dim), Dim), 2, 3) {
  const Vec<Dim> h = Vec<Dim>::Constant(0.1);
  Vec<Dim> c = Vec<Dim>::Constant(0.5);
  c[1] = 0.1 + 0.001;
  // fine samples: hundreds of points on the bottom face before the reduction
  std::vector<RigidBody<Dim>> bodies{make_body<Dim>(box_spec<Dim>(c, h), BodyMotion::dynamic, 0.005)};
  const auto walls = detect_contacts<Dim>(bodies, unit_walls<Dim>(), 0.01);
  check_bottom_corners<Dim>(walls, c, h, 0.0);
  for (const auto& k : walls) {
    CHECK_THAT(k.phi, WithinAbs(0.001, 1e-14));
    CHECK((k.normal - up<Dim>()).norm() == 0.0);
  }
  // the same box on a static floor body
  Vec<Dim> fc = Vec<Dim>::Constant(0.5), fh = Vec<Dim>::Constant(0.4);
  fc[1] = -0.05;
  fh[1] = 0.05;
  bodies.push_back(make_body<Dim>(box_spec<Dim>(fc, fh), BodyMotion::fixed, 0.005));
  const auto both = detect_contacts<Dim>(bodies, no_walls<Dim>(), 0.01);
  check_bottom_corners<Dim>(both, c, h, 0.0);
  for (const auto& k : both) {
    CHECK(k.body_a == 0);
    CHECK(k.body_b == 1);
    CHECK_THAT(k.phi, WithinAbs(0.001, 1e-14));
    CHECK((k.normal - up<Dim>()).norm() < 1e-14);
  }
}

TEMPLATE_TEST_CASE_SIG("stacked boxes: corners between the boxes and on the floor, normals b -> a",
                       "[unit][collision]", ((int Dim), Dim), 2, 3) {
  const Vec<Dim> h = Vec<Dim>::Constant(0.1);
  Vec<Dim> lower = Vec<Dim>::Constant(0.5), upper = Vec<Dim>::Constant(0.5);
  lower[1] = 0.1;
  upper[1] = 0.3 + 0.002;
  // upper box slightly smaller in x so that the lower box's corners are not the patch extremes
  Vec<Dim> hu = h;
  hu[0] = 0.08;
  std::vector<RigidBody<Dim>> bodies{make_body<Dim>(box_spec<Dim>(lower, h)),
                                     make_body<Dim>(box_spec<Dim>(upper, hu))};
  const auto contacts = detect_contacts<Dim>(bodies, unit_walls<Dim>(), 0.01);
  std::vector<Contact<Dim>> between, floor;
  for (const auto& k : contacts) (k.body_b == -1 ? floor : between).push_back(k);
  // pair contacts first (deterministic order), then walls
  REQUIRE(!contacts.empty());
  CHECK(contacts.front().body_b == 1);
  check_bottom_corners<Dim>(floor, lower, h, 0.0);
  REQUIRE(between.size() == (Dim == 2 ? 2u : 4u));
  for (const auto& k : between) {
    // a = 0 (the lower index, both dynamic), b = 1 above it: the normal points down
    CHECK(k.body_a == 0);
    CHECK((k.normal + up<Dim>()).norm() < 1e-14);
    CHECK_THAT(k.phi, WithinAbs(0.002, 1e-14));
    // at the corners of the upper box's bottom face
    CHECK_THAT(std::abs(k.point[0] - 0.5), WithinAbs(0.08, 1e-12));
    CHECK_THAT(k.point[1], WithinAbs(0.202, 1e-12));
  }
}

TEST_CASE("rotated box on an edge or a corner: contacts at the touching edge only",
          "[unit][collision]") {
  // 2D: a square turned 45 degrees touches the floor with one corner
  const double h = 0.1, gap = 0.003;
  std::vector<RigidBody<2>> b2{
      make_body<2>(box_spec<2>(Vec<2>(0.5, h * std::sqrt(2.0) + gap), Vec<2>(h, h), {0.25 * M_PI}))};
  const auto c2 = detect_contacts<2>(b2, unit_walls<2>(), 0.01);
  REQUIRE(c2.size() == 1);
  CHECK_THAT(c2[0].phi, WithinAbs(gap, 1e-12));
  CHECK((c2[0].point - Vec<2>(0.5, 0.0)).norm() < 1e-12);
  // 3D: turned 45 degrees about z, it touches the floor along an edge parallel to z: the two
  // ends of the edge
  std::vector<RigidBody<3>> b3{make_body<3>(
      box_spec<3>(Vec<3>(0.5, h * std::sqrt(2.0) + gap, 0.5), Vec<3>(h, h, 0.15), {0, 0, 0.25 * M_PI}))};
  const auto c3 = detect_contacts<3>(b3, unit_walls<3>(), 0.01);
  REQUIRE(c3.size() == 2);
  for (const auto& k : c3) {
    CHECK_THAT(k.phi, WithinAbs(gap, 1e-12));
    CHECK(std::abs(k.point[0] - 0.5) < 1e-12);
    CHECK_THAT(std::abs(k.point[2] - 0.5), WithinAbs(0.15, 1e-12));
  }
  // against a wall at x = 0 instead: the rotated box in 3D touching x- with its edge
  b3[0].position = Vec<3>(h * std::sqrt(2.0) + gap, 0.5, 0.5);
  const auto cx = detect_contacts<3>(b3, unit_walls<3>(), 0.01);
  REQUIRE(cx.size() == 2);
  for (const auto& k : cx) {
    CHECK(k.wall_face == 0);
    CHECK((k.normal - Vec<3>::UnitX()).norm() == 0.0);
    CHECK_THAT(k.phi, WithinAbs(gap, 1e-12));
  }
}

TEST_CASE("mesh (the 3D bunny) on the floor: a few contacts at its lowest points",
          "[unit][collision]") {
  ShapeSpec bunny;
  bunny.type = ShapeType::bunny;
  bunny.center = {0.5, 0.5, 0.5};
  bunny.size = 0.3;
  std::vector<RigidBody<3>> bodies{make_body<3>(bunny, BodyMotion::dynamic, 0.01)};
  // lower it until its lowest sample is 0.002 above the floor
  double lowest = 1e9;
  for (const auto& s : bodies[0].surface_samples()) lowest = std::min(lowest, bodies[0].to_world(s)[1]);
  bodies[0].position[1] -= lowest - 0.002;
  const auto c = detect_contacts<3>(bodies, unit_walls<3>(), 0.01);
  REQUIRE(!c.empty());
  CHECK(c.size() <= 4u);
  double min_phi = 1e9;
  for (const auto& k : c) {
    CHECK(k.body_b == -1);
    CHECK(k.wall_face == 2);
    CHECK(k.phi < 0.01);
    CHECK(k.phi >= 0.002 - 1e-12);
    CHECK(std::abs(k.point[1]) < 1e-12);
    min_phi = std::min(min_phi, k.phi);
  }
  CHECK_THAT(min_phi, WithinAbs(0.002, 1e-12));
  // rotated arbitrarily and pushed into the floor, it still reports its deepest point
  bodies[0].orientation = Eigen::Quaterniond(Eigen::AngleAxisd(1.0, Vec<3>(1, 2, 3).normalized()));
  lowest = 1e9;
  for (const auto& s : bodies[0].surface_samples()) lowest = std::min(lowest, bodies[0].to_world(s)[1]);
  bodies[0].position[1] -= lowest + 0.004;
  const auto d = detect_contacts<3>(bodies, unit_walls<3>(), 0.01);
  REQUIRE(!d.empty());
  CHECK_THAT(d.front().phi, WithinAbs(-0.004, 1e-12));
}

TEMPLATE_TEST_CASE_SIG("separated bodies and non-dynamic pairs give no contacts",
                       "[unit][collision]", ((int Dim), Dim), 2, 3) {
  Vec<Dim> a = Vec<Dim>::Constant(0.3), b = Vec<Dim>::Constant(0.3);
  b[0] = 0.3 + 0.2 + 0.011;
  std::vector<RigidBody<Dim>> bodies{make_body<Dim>(box_spec<Dim>(a, Vec<Dim>::Constant(0.1))),
                                     make_body<Dim>(box_spec<Dim>(b, Vec<Dim>::Constant(0.1)))};
  CHECK(detect_contacts<Dim>(bodies, unit_walls<Dim>(), 0.01).empty());
  // touching, but both fixed / kinematic: no contacts
  b[0] = 0.5;
  Vec<Dim> floor_c = Vec<Dim>::Constant(0.5);
  floor_c[1] = 0.05;
  std::vector<RigidBody<Dim>> still{make_body<Dim>(box_spec<Dim>(a, Vec<Dim>::Constant(0.1)), BodyMotion::fixed),
                                    make_body<Dim>(box_spec<Dim>(b, Vec<Dim>::Constant(0.1)), BodyMotion::fixed)};
  CHECK(detect_contacts<Dim>(still, unit_walls<Dim>(), 0.01).empty());
  BodySpec kin;
  kin.motion = BodyMotion::kinematic;
  kin.has_path = true;
  kin.path.axis = std::vector<double>(Dim, 1.0);
  kin.shape = box_spec<Dim>(b, Vec<Dim>::Constant(0.1));
  kin.density = 1.0;
  ShapePtr<Dim> ks = make_shape<Dim>(kin.shape, "test");
  still[1] = RigidBody<Dim>(kin, ks, mass_properties<Dim>(kin.shape, *ks, 1.0), 0.01);
  CHECK(detect_contacts<Dim>(still, unit_walls<Dim>(), 0.01).empty());
  // a dynamic body against the kinematic one: the dynamic body is a
  still[0] = make_body<Dim>(box_spec<Dim>(a, Vec<Dim>::Constant(0.1)));
  const auto k = detect_contacts<Dim>(std::vector<RigidBody<Dim>>{still[1], still[0]},
                                      no_walls<Dim>(), 0.01);
  REQUIRE(!k.empty());
  for (const auto& c : k) {
    CHECK(c.body_a == 1);
    CHECK(c.body_b == 0);
    CHECK(c.normal[0] < -0.99);  // a (at lower x) separates towards -x
  }
}

TEMPLATE_TEST_CASE_SIG("sphere against a box: one exact contact from the centre",
                       "[unit][collision]", ((int Dim), Dim), 2, 3) {
  Vec<Dim> c = Vec<Dim>::Constant(0.5);
  c[1] = 0.2 + 0.1 + 0.004;
  Vec<Dim> bc = Vec<Dim>::Constant(0.5);
  bc[1] = 0.1;
  std::vector<RigidBody<Dim>> bodies{make_body<Dim>(box_spec<Dim>(bc, Vec<Dim>::Constant(0.1)), BodyMotion::fixed),
                                     make_body<Dim>(sphere<Dim>(c, 0.1))};
  const auto k = detect_contacts<Dim>(bodies, no_walls<Dim>(), 0.01);
  REQUIRE(k.size() == 1);
  CHECK(k[0].body_a == 1);
  CHECK(k[0].body_b == 0);
  CHECK_THAT(k[0].phi, WithinAbs(0.004, 1e-14));
  CHECK((k[0].normal - up<Dim>()).norm() < 1e-12);
  Vec<Dim> top = c;
  top[1] = 0.2;
  CHECK((k[0].point - top).norm() < 1e-12);
  // the sphere as body b (a static ball under a dynamic box)
  std::vector<RigidBody<Dim>> swapped{make_body<Dim>(box_spec<Dim>(c, Vec<Dim>::Constant(0.1))),
                                      make_body<Dim>(sphere<Dim>(bc, 0.1), BodyMotion::fixed)};
  swapped[0].position[1] = 0.2 + 0.1 + 0.004;
  const auto s = detect_contacts<Dim>(swapped, no_walls<Dim>(), 0.01);
  REQUIRE(s.size() == 1);
  CHECK(s[0].body_a == 0);
  CHECK_THAT(s[0].phi, WithinAbs(0.004, 1e-14));
  CHECK((s[0].normal - up<Dim>()).norm() < 1e-12);
  Vec<Dim> ball_top = bc;
  ball_top[1] += 0.1;
  CHECK((s[0].point - ball_top).norm() < 1e-12);
}

TEMPLATE_TEST_CASE_SIG("the contact set is symmetric in the order of the bodies and "
                       "deterministic", "[unit][collision][property]", ((int Dim), Dim), 2, 3) {
  // a tilted box pressed onto another box: candidates from both directions
  Vec<Dim> a = Vec<Dim>::Constant(0.5), b = Vec<Dim>::Constant(0.5);
  a[1] = 0.3 + 0.0;
  b[1] = 0.15;
  const std::vector<double> tilt = Dim == 2 ? std::vector<double>{0.05} : std::vector<double>{0.03, 0.1, 0.05};
  const RigidBody<Dim> top = make_body<Dim>(box_spec<Dim>(a, Vec<Dim>::Constant(0.1), tilt));
  const RigidBody<Dim> bottom = make_body<Dim>(box_spec<Dim>(b, Vec<Dim>::Constant(0.06)));
  const auto ab = detect_contacts<Dim>({top, bottom}, no_walls<Dim>(), 0.01);
  const auto ba = detect_contacts<Dim>({bottom, top}, no_walls<Dim>(), 0.01);
  REQUIRE(!ab.empty());
  REQUIRE(ab.size() == ba.size());
  for (const auto& k : ab) {
    // relabelled: a <-> b, the normal reversed, the same midpoint and gap
    int matches = 0;
    for (const auto& m : ba) {
      const Vec<Dim> mk = k.point + 0.5 * k.phi * k.normal, mm = m.point + 0.5 * m.phi * m.normal;
      if ((mk - mm).norm() < 1e-9 && (k.normal + m.normal).norm() < 1e-9 &&
          std::abs(k.phi - m.phi) < 1e-12) {
        ++matches;
      }
    }
    CHECK(matches == 1);
    // the normal points from b to a: a's centre lies on its positive side
    const RigidBody<Dim>& body_a = k.body_a == 0 ? top : bottom;
    CHECK(k.normal.dot(body_a.position - k.point) > 0.0);
  }
  // the same input gives the same output
  const auto again = detect_contacts<Dim>({top, bottom}, no_walls<Dim>(), 0.01);
  REQUIRE(again.size() == ab.size());
  for (std::size_t i = 0; i < ab.size(); ++i) {
    CHECK(again[i].point == ab[i].point);
    CHECK(again[i].phi == ab[i].phi);
  }
}

TEST_CASE("Walls::from_scene reads the wall faces, friction and restitution", "[unit][collision]") {
  SceneDesc scene;
  scene.dim = 2;
  scene.domain.lower = {0, 0};
  scene.domain.upper = {2, 1};
  scene.domain.cells = {64, 32};
  scene.domain.boundary[3] = BoundaryType::open;
  scene.domain.wall_friction = 0.7;
  scene.domain.wall_restitution = 0.2;
  const auto w = Walls<2>::from_scene(scene);
  CHECK(w.is_wall[0]);
  CHECK(w.is_wall[2]);
  CHECK_FALSE(w.is_wall[3]);
  CHECK(w.upper == Vec<2>(2, 1));
  CHECK(w.friction == 0.7);
  CHECK(w.restitution == 0.2);
  CHECK(w.face_distance(1, Vec<2>(1.5, 0.5)) == 0.5);
  CHECK(Walls<2>::face_normal(1) == Vec<2>(-1, 0));
  // an open face takes no contacts
  std::vector<RigidBody<2>> bodies{make_body<2>(sphere<2>(Vec<2>(1.0, 0.95), 0.1))};
  CHECK(detect_contacts<2>(bodies, w, 0.01).empty());
}

TEMPLATE_TEST_CASE_SIG("equal stacked boxes: edges that line up give the corners with the face "
                       "normal only", "[unit][collision]", ((int Dim), Dim), 2, 3) {
  const Vec<Dim> h = Vec<Dim>::Constant(0.1);
  Vec<Dim> lower = Vec<Dim>::Constant(0.5), upper = Vec<Dim>::Constant(0.5);
  lower[1] = 0.1;
  upper[1] = 0.3 + 0.001;
  std::vector<RigidBody<Dim>> bodies{make_body<Dim>(box_spec<Dim>(lower, h)),
                                     make_body<Dim>(box_spec<Dim>(upper, h))};
  const auto contacts = detect_contacts<Dim>(bodies, no_walls<Dim>(), 0.01);
  Vec<Dim> c = upper;
  c[1] = 0.2;
  std::vector<Contact<Dim>> shifted;
  for (auto k : contacts) {
    // compare on the lower box's top face: the points lie there (on body b's surface) or on
    // the upper box's bottom face, 0.001 above
    CHECK((k.normal + up<Dim>()).norm() == 0.0);
    CHECK_THAT(k.phi, WithinAbs(0.001, 1e-14));
    k.point[1] = std::min(k.point[1], 0.2 + 1e-12);
    shifted.push_back(k);
  }
  // the corners of the shared face, each once
  REQUIRE(shifted.size() == (Dim == 2 ? 2u : 4u));
  for (auto& k : shifted) k.point[1] = std::abs(k.point[1] - 0.2) < 2e-3 ? 0.2 : k.point[1];
  check_bottom_corners<Dim>(shifted, c, h, 0.2);
}

TEST_CASE("parallel edges of diagonal neighbours: the two ends of the edge, normal across",
          "[unit][collision]") {
  // two unit-aligned boxes whose x-parallel edges face each other across a diagonal gap
  const double h = 0.05, g = 0.001;
  const double off = 2.0 * h + g / std::sqrt(2.0);
  std::vector<RigidBody<3>> bodies{
      make_body<3>(box_spec<3>(Vec<3>(0.5, 0.5, 0.5), Vec<3>(h, h, h))),
      make_body<3>(box_spec<3>(Vec<3>(0.5, 0.5 + off, 0.5 + off), Vec<3>(h, h, h)))};
  const auto c = detect_contacts<3>(bodies, no_walls<3>(), 0.01);
  REQUIRE(c.size() == 2u);
  for (const auto& k : c) {
    // b = 1 lies up and behind: the normal from b to a points down and to the front
    CHECK((k.normal - Vec<3>(0, -1, -1).normalized()).norm() < 1e-9);
    CHECK_THAT(k.phi, WithinAbs(g, 1e-12));
    CHECK_THAT(std::abs(k.point[0] - 0.5), WithinAbs(h, 1e-12));
  }
}

TEST_CASE("reduce_contacts: a rectangular patch keeps its four corners, deepest first",
          "[unit][collision]") {
  // a 9 x 5 lattice of candidates on a rotated rectangle in the plane normal to n, one corner
  // slightly deeper
  const Vec<3> n = Vec<3>(0.2, 1.0, -0.1).normalized();
  const Vec<3> t1 = n.unitOrthogonal(), t2 = n.cross(t1);
  std::vector<Contact<3>> cand;
  for (int i = 0; i <= 8; ++i) {
    for (int j = 0; j <= 4; ++j) {
      Contact<3> k;
      k.body_a = 0;
      k.normal = n;
      k.phi = (i == 8 && j == 0) ? 0.0009 : 0.001;
      k.point = Vec<3>(1, 2, 3) + 0.01 * i * t1 + 0.01 * j * t2;
      cand.push_back(k);
    }
  }
  const auto r = reduce_contacts<3>(cand);
  REQUIRE(r.size() == 4u);
  CHECK(r[0].phi == 0.0009);
  for (const auto& k : r) {
    const Vec<3> d = k.point - Vec<3>(1, 2, 3);
    const double u = d.dot(t1) / 0.01, v = d.dot(t2) / 0.01;
    CHECK((std::abs(u) < 1e-9 || std::abs(u - 8) < 1e-9));
    CHECK((std::abs(v) < 1e-9 || std::abs(v - 4) < 1e-9));
  }
  // a second face at 90 degrees (normal t1, spanned by n and t2) stays a second patch
  std::vector<Contact<3>> two = cand;
  for (auto k : cand) {
    const Vec<3> d = k.point - Vec<3>(1, 2, 3);
    k.point = Vec<3>(1, 2, 3) + d.dot(t1) * n + d.dot(t2) * t2 - 0.05 * t1;
    k.normal = t1;
    two.push_back(k);
  }
  CHECK(reduce_contacts<3>(two).size() == 8u);
}

TEMPLATE_TEST_CASE_SIG("a box on a static halfspace body: its corners", "[unit][collision]",
                       ((int Dim), Dim), 2, 3) {
  ShapeSpec plane;
  plane.type = ShapeType::halfspace;
  plane.normal = as_std<Dim>(up<Dim>());
  plane.offset = 0.2;
  BodySpec spec;
  spec.motion = BodyMotion::fixed;
  spec.shape = plane;
  ShapePtr<Dim> s = make_shape<Dim>(plane, "test");
  MassProperties<Dim> none;  // an unbounded fixed body has no mass (as make_bodies does)
  const RigidBody<Dim> ground(spec, s, none, 0.01);
  CHECK(ground.surface_samples().empty());
  const Vec<Dim> h = Vec<Dim>::Constant(0.1);
  Vec<Dim> c = Vec<Dim>::Constant(0.5);
  c[1] = 0.3 + 0.002;
  const std::vector<RigidBody<Dim>> bodies{ground, make_body<Dim>(box_spec<Dim>(c, h))};
  const auto contacts = detect_contacts<Dim>(bodies, no_walls<Dim>(), 0.01);
  check_bottom_corners<Dim>(contacts, c, h, 0.2);
  for (const auto& k : contacts) {
    CHECK(k.body_a == 1);
    CHECK(k.body_b == 0);
    CHECK_THAT(k.phi, WithinAbs(0.002, 1e-14));
    CHECK((k.normal - up<Dim>()).norm() < 1e-15);
  }
}

TEST_CASE("2D bunny silhouette on the floor and in a static bowl", "[unit][collision]") {
  ShapeSpec bunny;
  bunny.type = ShapeType::bunny;
  bunny.center = {0.5, 0.5};
  bunny.size = 0.3;
  bunny.rotation = {0.3};
  std::vector<RigidBody<2>> bodies{make_body<2>(bunny, BodyMotion::dynamic, 0.005)};
  double lowest = 1e9;
  for (const auto& s : bodies[0].surface_samples()) lowest = std::min(lowest, bodies[0].to_world(s)[1]);
  bodies[0].position[1] -= lowest - 0.001;
  const auto c = detect_contacts<2>(bodies, unit_walls<2>(), 0.01);
  REQUIRE(!c.empty());
  CHECK(c.size() <= 4u);
  CHECK_THAT(c.front().phi, WithinAbs(0.001, 1e-12));
  for (const auto& k : c) CHECK((k.normal - up<2>()).norm() == 0.0);
  // dropped into a static bowl (a concave body): contacts with the inner wall, normals from
  // the bowl towards the bunny (upwards and inwards), the gap at least the smallest one
  ShapeSpec bowl;
  bowl.type = ShapeType::bowl;
  bowl.center = {0.5, 0.5};
  bowl.radius = 0.3;
  bowl.thickness = 0.05;
  ShapeSpec small = bunny;
  small.size = 0.15;
  small.center = {0.5, 0.4};
  bodies = {make_body<2>(small, BodyMotion::dynamic, 0.005), make_body<2>(bowl, BodyMotion::fixed, 0.005)};
  // lower the bunny until it almost touches the bowl's inner surface
  double gap = 1e9;
  for (const auto& s : bodies[0].surface_samples()) gap = std::min(gap, bodies[1].distance(bodies[0].to_world(s)));
  bodies[0].position[1] -= gap - 0.002;
  gap = 1e9;
  for (const auto& s : bodies[0].surface_samples()) gap = std::min(gap, bodies[1].distance(bodies[0].to_world(s)));
  const auto d = detect_contacts<2>(bodies, no_walls<2>(), 0.01);
  REQUIRE(!d.empty());
  double min_phi = 1e9;
  for (const auto& k : d) {
    CHECK(k.body_a == 0);
    CHECK(k.body_b == 1);
    CHECK(k.normal[1] > 0.0);
    CHECK(std::abs(k.normal.norm() - 1.0) < 1e-12);
    CHECK(k.normal.dot(Vec<2>(0.5, 0.5) - k.point) > 0.0);  // towards the bowl centre
    min_phi = std::min(min_phi, k.phi);
  }
  // the closest bunny sample is among the contacts (measured: 3 contacts, min phi = gap).
  // The bowl's samples could only find a closer pair where the bunny's edge points miss the
  // true nearest point: by at most (spacing/2)^2 / (2 R_inner) = 1.25e-5 (bound 2e-5)
  CHECK(min_phi <= gap + 1e-12);
  CHECK(min_phi > gap - 2e-5);
}

TEST_CASE("detection does not depend on the number of threads", "[unit][collision]") {
  // a small 3D pile of rotated boxes and spheres on the floor
  std::vector<RigidBody<3>> bodies;
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 3; ++j) {
      const Vec<3> c(0.2 + 0.105 * i, 0.05 + 0.1005 * j, 0.5);
      if ((i + j) % 3 == 0) {
        bodies.push_back(make_body<3>(sphere<3>(c, 0.05)));
      } else {
        bodies.push_back(make_body<3>(box_spec<3>(c, Vec<3>::Constant(0.05), {0.02 * i, 0.01 * j, 0.03})));
      }
    }
  }
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto one = detect_contacts<3>(bodies, unit_walls<3>(), 0.01);
  omp_set_num_threads(2);
  const auto two = detect_contacts<3>(bodies, unit_walls<3>(), 0.01);
  omp_set_num_threads(threads);
  REQUIRE(one.size() > 20u);
  REQUIRE(one.size() == two.size());
  for (std::size_t k = 0; k < one.size(); ++k) {
    CHECK(one[k].body_a == two[k].body_a);
    CHECK(one[k].body_b == two[k].body_b);
    CHECK(one[k].point == two[k].point);
    CHECK(one[k].normal == two[k].normal);
    CHECK(one[k].phi == two[k].phi);
  }
}

TEMPLATE_TEST_CASE_SIG("a sphere in a groove (one concave body): one contact per face",
                       "[unit][collision]", ((int Dim), Dim), 2, 3) {
  // a V-groove: the union of two boxes tilted by +-45 degrees about z, their inner faces
  // meeting below x = 0.5 at y = 0.3; a sphere of radius r above it touches both faces
  const double r = 0.05, gap = 0.002;
  ShapeSpec groove;
  groove.type = ShapeType::set_union;
  for (int side = 0; side < 2; ++side) {
    const double s = side ? 1.0 : -1.0;
    // inner face through (0.5, 0.3) with normal (-s, 1)/sqrt(2), extending 0.3 along it
    const Vec<2> n2 = Vec<2>(-s, 1.0).normalized();
    const Vec<2> c2 = Vec<2>(0.5, 0.3) - 0.05 * n2 + Vec<2>(s, 1.0).normalized() * 0.15;
    Vec<Dim> c = Vec<Dim>::Constant(0.5), h = Vec<Dim>::Constant(0.15);
    c[0] = c2[0];
    c[1] = c2[1];
    h[1] = 0.05;
    h[0] = 0.15;
    std::vector<double> rot = Dim == 2 ? std::vector<double>{s * 0.25 * M_PI}
                                       : std::vector<double>{0.0, 0.0, s * 0.25 * M_PI};
    groove.shapes.push_back(box_spec<Dim>(c, h, rot));
  }
  std::vector<RigidBody<Dim>> bodies{make_body<Dim>(groove, BodyMotion::fixed, 0.01)};
  Vec<Dim> centre = Vec<Dim>::Constant(0.5);
  centre[1] = 0.3 + (r + gap) * std::sqrt(2.0);
  bodies.push_back(make_body<Dim>(sphere<Dim>(centre, r)));
  const auto c = detect_contacts<Dim>(bodies, no_walls<Dim>(), 0.01);
  REQUIRE(c.size() == 2u);
  for (const auto& k : c) {
    CHECK(k.body_a == 1);
    CHECK(k.body_b == 0);
    // exact: the nearest face from the centre query, the other face from its samples'
    // tangent plane (the shape library's box gradient is numerical: 1e-9)
    CHECK_THAT(k.phi, WithinAbs(gap, 1e-9));
    CHECK_THAT(std::abs(k.normal[0]), WithinAbs(std::sqrt(0.5), 1e-9));
    CHECK_THAT(k.normal[1], WithinAbs(std::sqrt(0.5), 1e-9));
    // the point on the face is where the normal through the centre meets it
    CHECK((k.point + (r + gap) * k.normal - centre).norm() < 1e-9);
  }
  CHECK(c[0].normal[0] * c[1].normal[0] < 0.0);
}
