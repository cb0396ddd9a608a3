/// \file test_rigid_body.cpp
/// Rigid-body state and integration: cross-product helpers, free flight (exact), gravity
/// applied by the caller (the symplectic-Euler parabola), 2D rotation, 3D torque-free motion
/// (angular momentum, energy, unit quaternions, second-order convergence), kinematic paths, the
/// posed SDF, surface samples and make_bodies.

#include <catch2/catch.hpp>
#include <cmath>
#include <nlohmann/json.hpp>
#include <random>

#include "reference/app/scene_file.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/geometry/shape_tools.hpp"
#include "reference/rigid/rigid_body.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using monolith::testing::as_std;
using monolith::testing::kPi;
using Catch::Matchers::WithinAbs;
using Catch::Matchers::WithinRel;

namespace {

template <int Dim>
BodySpec box_body(const Vec<Dim>& c, const Vec<Dim>& h, std::vector<double> rotation = {},
                  BodyMotion motion = BodyMotion::dynamic) {
  BodySpec b;
  b.name = "box";
  b.motion = motion;
  b.shape.type = ShapeType::box;
  b.shape.center = as_std<Dim>(c);
  b.shape.half_size = as_std<Dim>(h);
  b.shape.rotation = std::move(rotation);
  b.density = 500.0;
  return b;
}

template <int Dim>
RigidBody<Dim> build(const BodySpec& spec, double spacing = 0.0) {
  ShapePtr<Dim> shape = make_shape<Dim>(spec.shape, "test");
  const auto props = mass_properties<Dim>(spec.shape, *shape, spec.density);
  return RigidBody<Dim>(spec, std::move(shape), props, spacing);
}

/// A random pose: centre of mass moved by up to 1, a random rotation.
void random_pose(RigidBody<2>& b, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  b.position += Vec<2>(u(rng), u(rng));
  b.orientation = kPi * u(rng);
}
void random_pose(RigidBody<3>& b, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  b.position += Vec<3>(u(rng), u(rng), u(rng));
  b.orientation = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized();
}

/// Specs of several shape types (rest pose) for the generic checks.
template <int Dim>
std::vector<BodySpec> sample_specs() {
  std::vector<BodySpec> specs;
  const Vec<Dim> c = Vec<Dim>::Constant(0.5);
  specs.push_back(box_body<Dim>(c, Vec<Dim>::Constant(0.1), Dim == 2 ? std::vector<double>{0.3}
                                                                    : std::vector<double>{0.1, 0.2, 0.3}));
  BodySpec sphere = specs.front();
  sphere.shape = ShapeSpec{};
  sphere.shape.type = ShapeType::sphere;
  sphere.shape.center = as_std<Dim>(c);
  sphere.shape.radius = 0.1;
  specs.push_back(sphere);
  BodySpec bowl = sphere;
  bowl.shape.type = ShapeType::bowl;
  bowl.shape.radius = 0.15;
  bowl.shape.thickness = 0.03;
  specs.push_back(bowl);
  BodySpec bunny = sphere;
  bunny.shape = ShapeSpec{};
  bunny.shape.type = ShapeType::bunny;
  bunny.shape.center = as_std<Dim>(c);
  bunny.shape.size = 0.3;
  specs.push_back(bunny);
  BodySpec uni = sphere;
  uni.shape = ShapeSpec{};
  uni.shape.type = ShapeType::set_union;
  uni.shape.shapes = {box_body<Dim>(c, Vec<Dim>::Constant(0.05)).shape, sphere.shape};
  uni.shape.shapes[1].center[0] += 0.1;
  specs.push_back(uni);
  return specs;
}

}  // namespace

TEST_CASE("cross-product helpers: 2D is the z-slice of 3D", "[unit][rigid]") {
  const Vec<2> r(0.3, -0.7), f(1.1, 0.4);
  const AngularVec<2> w(2.5);
  const Vec<3> r3(r[0], r[1], 0), f3(f[0], f[1], 0), w3(0, 0, w[0]);
  const Vec<2> wr = angular_cross<2>(w, r);
  const Vec<3> wr3 = angular_cross<3>(w3, r3);
  CHECK((wr - wr3.head<2>()).norm() < 1e-15);
  CHECK(std::abs(moment<2>(r, f)[0] - moment<3>(r3, f3)[2]) < 1e-15);
  CHECK((moment<3>(r3, f3) - r3.cross(f3)).norm() == 0.0);
}

TEMPLATE_TEST_CASE_SIG("free flight is exact; gravity by the caller gives the symplectic-Euler "
                       "parabola", "[unit][rigid]", ((int Dim), Dim), 2, 3) {
  RigidBody<Dim> b = build<Dim>(box_body<Dim>(Vec<Dim>::Constant(0.5), Vec<Dim>::Constant(0.1)));
  const Vec<Dim> x0 = b.position;
  Vec<Dim> v0 = Vec<Dim>::Zero();
  v0[0] = 0.7;
  v0[1] = 1.3;
  b.velocity = v0;
  const double dt = 1e-3;
  for (int n = 1; n <= 1000; ++n) b.integrate(dt, n * dt);
  CHECK((b.position - (x0 + v0 * 1.0)).norm() < 1e-12);
  CHECK((b.velocity - v0).norm() == 0.0);
  // gravity: v += dt g, then x += dt v gives x_n = x0 + v0 t + g dt^2 n (n + 1) / 2
  Vec<Dim> g = Vec<Dim>::Zero();
  g[1] = -9.81;
  b.position = x0;
  b.velocity = v0;
  const int steps = 500;
  for (int n = 1; n <= steps; ++n) {
    b.velocity += dt * g;
    b.integrate(dt, n * dt);
  }
  const double t = steps * dt;
  const Vec<Dim> discrete = x0 + v0 * t + g * (dt * dt * steps * (steps + 1) / 2.0);
  CHECK((b.position - discrete).norm() < 1e-12);
  // differs from the exact parabola by g dt t / 2 (first order)
  const Vec<Dim> parabola = x0 + v0 * t + 0.5 * g * t * t;
  CHECK_THAT((b.position - parabola).norm(), WithinRel(0.5 * 9.81 * dt * t, 1e-9));
}

TEST_CASE("2D rotation is exact", "[unit][rigid]") {
  RigidBody<2> b = build<2>(box_body<2>(Vec<2>(0.5, 0.5), Vec<2>(0.2, 0.1)));
  b.angular_velocity[0] = 3.0;
  const Vec<2> corner_rest(0.7, 0.6);
  for (int n = 1; n <= 1000; ++n) b.integrate(1e-3, n * 1e-3);
  CHECK_THAT(b.orientation, WithinAbs(3.0, 1e-12));
  const Vec<2> expected = Eigen::Rotation2Dd(3.0) * Vec<2>(0.2, 0.1) + Vec<2>(0.5, 0.5);
  CHECK((b.to_world(corner_rest) - expected).norm() < 1e-12);
  CHECK_THAT(b.angular_velocity[0], WithinAbs(3.0, 0.0));
}

TEST_CASE("3D torque-free rotation: angular momentum and energy conserved, unit quaternion, "
          "second-order convergence", "[unit][rigid][convergence]") {
  // an asymmetric box, tilted so that the body axes are not principal, spinning near its
  // unstable intermediate axis (the tumbling "tennis racket" motion)
  const BodySpec spec = box_body<3>(Vec<3>(0, 0, 0), Vec<3>(0.3, 0.2, 0.1), {0.4, -0.3, 0.2});
  auto run = [&](double dt, double t_end, double* max_l_err, double* max_e_err,
                 double* max_q_err, int* flips = nullptr) {
    RigidBody<3> b = build<3>(spec);
    const Mat<3> r0 = rotation_matrix<3>(spec.shape.rotation);
    b.angular_velocity = r0 * Vec<3>(0.05, 4.0, 0.03);  // about the middle axis of the box
    const Vec<3> l0 = b.angular_momentum();
    const double e0 = b.kinetic_energy();
    const int steps = static_cast<int>(std::lround(t_end / dt));
    double previous_along = 0.0;
    for (int n = 1; n <= steps; ++n) {
      b.integrate(dt, n * dt);
      if (max_l_err) *max_l_err = std::max(*max_l_err, (b.angular_momentum() - l0).norm() / l0.norm());
      if (max_e_err) *max_e_err = std::max(*max_e_err, std::abs(b.kinetic_energy() - e0) / e0);
      if (max_q_err) *max_q_err = std::max(*max_q_err, std::abs(b.orientation.norm() - 1.0));
      if (flips) {
        // sign changes of the spin about the middle axis of the box
        const double along = (b.rotation().transpose() * b.angular_velocity).dot(r0.col(1));
        if (n > 1 && along * previous_along < 0.0) ++*flips;
        previous_along = along;
      }
    }
    return b;
  };
  double l_err = 0, e_err = 0, q_err = 0;
  int flips = 0;
  run(1e-2, 20.0, &l_err, &e_err, &q_err, &flips);
  // 2000 steps through three flips. The splitting keeps L exactly in exact arithmetic; the
  // measured |dL|/|L| 1.4e-12 is rounding accumulated over the steps (~7e-16 per step, bound
  // 1e-11). Energy: measured 2.0e-5, bounded, no drift (the O(dt^2) error of the splitting;
  // bound 1e-4). |q| - 1: measured 2.2e-16 (bound 1e-14).
  CHECK(l_err < 1e-11);
  CHECK(e_err < 1e-4);
  CHECK(q_err < 1e-14);
  // the body actually tumbles: the spin about the middle axis reverses (measured 3 times)
  CHECK(flips >= 2);
  // energy error falls ~4x when dt halves (second order)
  double e1 = 0, e2 = 0;
  run(2e-2, 5.0, nullptr, &e1, nullptr);
  run(1e-2, 5.0, nullptr, &e2, nullptr);
  CHECK(e2 < 0.35 * e1);
  // orientation error against a fine reference at t = 2: second order
  const RigidBody<3> ref = run(2.5e-4, 2.0, nullptr, nullptr, nullptr);
  const RigidBody<3> a = run(1e-2, 2.0, nullptr, nullptr, nullptr);
  const RigidBody<3> b = run(5e-3, 2.0, nullptr, nullptr, nullptr);
  const double ea = (a.rotation() - ref.rotation()).norm();
  const double eb = (b.rotation() - ref.rotation()).norm();
  CHECK(eb < 0.35 * ea);
}

TEMPLATE_TEST_CASE_SIG("kinematic path: positions and velocities exact; fixed bodies stay",
                       "[unit][rigid]", ((int Dim), Dim), 2, 3) {
  BodySpec spec = box_body<Dim>(Vec<Dim>::Constant(0.5), Vec<Dim>::Constant(0.1), {}, BodyMotion::kinematic);
  spec.has_path = true;
  spec.path.axis = std::vector<double>(Dim, 0.0);
  spec.path.axis[0] = 1.0;
  spec.path.axis[1] = 0.5;
  spec.path.amplitude = 0.2;
  spec.path.frequency = 1.5;
  RigidBody<Dim> b = build<Dim>(spec);
  const Vec<Dim> c0 = b.position;
  const Vec<Dim> axis = to_vec<Dim>(spec.path.axis);
  const double w = 2.0 * kPi * 1.5;
  for (double t : {0.0, 0.1, 0.37, 1.0, 2.25}) {
    b.integrate(0.01, t);
    CHECK((b.position - (c0 + axis * 0.2 * std::sin(w * t))).norm() < 1e-15);
    CHECK((b.velocity - axis * (0.2 * w * std::cos(w * t))).norm() < 1e-13);
    // the velocity is the derivative of the position (central difference, O(h^2))
    const double h = 1e-5;
    RigidBody<Dim> p = b, m = b;
    p.set_kinematic_state(t + h);
    m.set_kinematic_state(t - h);
    CHECK(((p.position - m.position) / (2 * h) - b.velocity).norm() < 1e-6);
  }
  CHECK(b.kinetic_energy() == 0.0);
  // fixed: nothing moves whatever the velocity fields say
  BodySpec fixed = box_body<Dim>(Vec<Dim>::Constant(0.5), Vec<Dim>::Constant(0.1), {}, BodyMotion::fixed);
  fixed.velocity = std::vector<double>(Dim, 1.0);
  RigidBody<Dim> f = build<Dim>(fixed);
  const Vec<Dim> before = f.position;
  f.integrate(0.1, 0.1);
  CHECK(f.position == before);
  CHECK(f.velocity.norm() == 0.0);
  CHECK(f.motion == BodyMotion::fixed);
}

TEMPLATE_TEST_CASE_SIG("posed SDF: distance(to_world(x)) equals the rest distance, gradients "
                       "rotate, bounds hold the posed shape", "[unit][rigid][property]",
                       ((int Dim), Dim), 2, 3) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  for (const BodySpec& spec : sample_specs<Dim>()) {
    INFO(enum_name(spec.shape.type));
    RigidBody<Dim> b = build<Dim>(spec, 0.02);
    const ShapePtr<Dim> rest = b.rest_shape();
    for (int pose = 0; pose < 5; ++pose) {
      random_pose(b, rng);
      const ShapePtr<Dim> posed = b.posed_shape();
      const Mat<Dim> r = b.rotation();
      CHECK((r.transpose() * r - Mat<Dim>::Identity()).norm() < 1e-14);
      for (int k = 0; k < 20; ++k) {
        Vec<Dim> x = Vec<Dim>::Constant(0.5);
        for (int a = 0; a < Dim; ++a) x[a] += u(rng);
        const Vec<Dim> xw = b.to_world(x);
        CHECK((b.to_rest(xw) - x).norm() < 1e-14);
        CHECK_THAT(b.distance(xw), WithinAbs(rest->distance(x), 1e-12));
        CHECK_THAT(posed->distance(xw), WithinAbs(rest->distance(x), 1e-12));
        CHECK((b.gradient(xw) - r * rest->gradient(x)).norm() < 1e-9);
      }
      const Box<Dim> box = b.bounds();
      for (const auto& s : b.surface_samples()) CHECK(box.contains(b.to_world(s)));
      CHECK(posed->bounds().isApprox(box));
    }
  }
}

TEMPLATE_TEST_CASE_SIG("point velocity is the time derivative of a material point",
                       "[unit][rigid]", ((int Dim), Dim), 2, 3) {
  RigidBody<Dim> b = build<Dim>(box_body<Dim>(Vec<Dim>::Constant(0.5), Vec<Dim>(Vec<Dim>::LinSpaced(0.1, 0.2))));
  b.velocity = Vec<Dim>::LinSpaced(0.3, -0.4);
  b.angular_velocity = AngularVec<Dim>::LinSpaced(1.5, 2.0);
  const Vec<Dim> x_rest = Vec<Dim>::Constant(0.62);
  const Vec<Dim> x0 = b.to_world(x_rest);
  const Vec<Dim> v = b.point_velocity(x0);
  // one tiny step: the material point moves by dt * point velocity + O(dt^2)
  const double dt = 1e-6;
  RigidBody<Dim> moved = b;
  moved.integrate(dt, dt);
  CHECK(((moved.to_world(x_rest) - x0) / dt - v).norm() < 1e-5);
  // generalised velocity round trip
  BodyVec<Dim> q = b.generalized_velocity();
  CHECK(q.template head<Dim>() == b.velocity);
  q *= 2.0;
  b.set_generalized_velocity(q);
  CHECK(b.velocity == q.template head<Dim>());
  CHECK(b.angular_velocity == q.template tail<kAngularDofs<Dim>>());
}

TEMPLATE_TEST_CASE_SIG("surface samples lie on the surface; box samples include the corners",
                       "[unit][rigid]", ((int Dim), Dim), 2, 3) {
  for (const BodySpec& spec : sample_specs<Dim>()) {
    INFO(enum_name(spec.shape.type));
    const RigidBody<Dim> b = build<Dim>(spec, 0.02);
    const auto& s = b.surface_samples();
    REQUIRE(s.size() > 10);
    double worst = 0.0;
    for (const auto& x : s) worst = std::max(worst, std::abs(b.rest_shape()->distance(x)));
    // the 3D bunny's SDF is a cached trilinear look-up near the surface: its error is bounded
    // by the cache spacing (size / 64) squared over the curvature radius; others are exact
    CHECK(worst < (spec.shape.type == ShapeType::bunny && Dim == 3 ? 2e-3 : 1e-9));
  }
  // an axis-aligned box: 2^Dim corners among the samples, spacing 0.05 on faces of side 0.2
  const RigidBody<Dim> box =
      build<Dim>(box_body<Dim>(Vec<Dim>::Zero(), Vec<Dim>::Constant(0.1)), 0.05);
  int corners = 0;
  for (const auto& x : box.surface_samples()) {
    if ((x.cwiseAbs() - Vec<Dim>::Constant(0.1)).cwiseAbs().maxCoeff() < 1e-15) ++corners;
  }
  CHECK(corners == (1 << Dim));
  // nodes of a 5^Dim lattice on the boundary: 5^Dim - 3^Dim
  CHECK(static_cast<int>(box.surface_samples().size()) == (Dim == 2 ? 25 - 9 : 125 - 27));
}

TEST_CASE("make_bodies: every motion type from a scene, spacing dx/2", "[unit][rigid]") {
  const nlohmann::json j = R"({
    "format": "monolith-scene/1", "dim": 2,
    "domain": {"lower": [0, 0], "upper": [1, 1], "cells": [32, 32]},
    "bodies": [
      {"name": "ball", "shape": {"type": "sphere", "center": [0.3, 0.5], "radius": 0.1},
       "density": 800, "velocity": [1, 2], "angular_velocity": 3, "friction": 0.4,
       "restitution": 0.5},
      {"name": "floor", "motion": "static",
       "shape": {"type": "box", "center": [0.5, 0.05], "half_size": [0.5, 0.05]}},
      {"name": "piston", "motion": "kinematic", "density": 100,
       "shape": {"type": "box", "center": [0.7, 0.5], "half_size": [0.05, 0.1]},
       "path": {"axis": [0, 1], "amplitude": 0.1, "frequency": 2}}
    ]})"_json;
  const SceneDesc scene = parse_scene(j, "test", ".");
  const auto bodies = make_bodies<2>(scene);
  REQUIRE(bodies.size() == 3);
  CHECK(bodies[0].name == "ball");
  CHECK(bodies[0].motion == BodyMotion::dynamic);
  CHECK(bodies[1].motion == BodyMotion::fixed);
  CHECK(bodies[2].motion == BodyMotion::kinematic);
  CHECK_THAT(bodies[0].mass, WithinRel(800 * kPi * 0.01, 1e-14));
  CHECK((bodies[0].velocity - Vec<2>(1, 2)).norm() == 0.0);
  CHECK(bodies[0].angular_velocity[0] == 3.0);
  CHECK(bodies[0].friction == 0.4);
  CHECK(bodies[0].restitution == 0.5);
  CHECK(bodies[0].is_sphere());
  CHECK_THAT(bodies[0].sample_spacing(), WithinRel(0.5 / 32, 1e-14));
  CHECK(bodies[1].sample_spacing() == bodies[0].sample_spacing());
  CHECK(bodies[2].has_path);
  CHECK_THAT(bodies[2].velocity[1], WithinRel(0.1 * 2 * kPi * 2, 1e-14));
  // the mass of a fixed body is not used; its position is its centre of mass
  CHECK((bodies[1].position - Vec<2>(0.5, 0.05)).norm() < 1e-15);
}

TEMPLATE_TEST_CASE_SIG("boxes: exact gradient, face normals and normal cones", "[unit][rigid]",
                       ((int Dim), Dim), 2, 3) {
  const std::vector<double> rot = Dim == 2 ? std::vector<double>{0.4} : std::vector<double>{0.2, -0.3, 0.4};
  RigidBody<Dim> b = build<Dim>(box_body<Dim>(Vec<Dim>::Constant(0.5), Vec<Dim>::LinSpaced(0.1, 0.2), rot));
  std::mt19937 rng(3);
  random_pose(b, rng);
  const Mat<Dim> r = b.rotation() * rotation_matrix<Dim>(rot);  // box frame -> world
  auto world = [&](const Vec<Dim>& y) {  // box-frame offset -> world point
    return b.to_world(Vec<Dim>(rotation_matrix<Dim>(rot) * y + Vec<Dim>::Constant(0.5)));
  };
  const Vec<Dim> h = Vec<Dim>::LinSpaced(0.1, 0.2);
  // away from edges the gradient is the numerical one of the posed distance
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  for (int k = 0; k < 50; ++k) {
    Vec<Dim> y;
    for (int a = 0; a < Dim; ++a) y[a] = u(rng);
    const Vec<Dim> x = world(y);
    const Vec<Dim> g = b.gradient(x);
    CHECK(std::abs(g.norm() - 1.0) < 1e-14);
    Vec<Dim> fd;
    const double step = 1e-7;
    for (int a = 0; a < Dim; ++a) {
      Vec<Dim> e = Vec<Dim>::Zero();
      e[a] = step;
      fd[a] = (b.distance(x + e) - b.distance(x - e)) / (2 * step);
    }
    // central differences match up to O(step^2 / d) and rounding, except within a step of a
    // kink: a face plane, or inside the box where two faces are equally near (skipped)
    const Vec<Dim> q = y.cwiseAbs() - h;
    bool near_kink = q.cwiseAbs().minCoeff() < 1e-4;
    for (int a = 0; a < Dim; ++a) {
      for (int c = a + 1; c < Dim; ++c) near_kink = near_kink || (q.maxCoeff() < 0.0 && std::abs(q[a] - q[c]) < 1e-4);
    }
    if (!near_kink) CHECK((fd - g).norm() < 1e-6);
  }
  // a face centre: one face, its normal; the cone test is the plain cosine
  Vec<Dim> y = Vec<Dim>::Zero();
  y[0] = h[0];
  Vec<Dim> n;
  REQUIRE(b.box_face_normal(world(y), &n));
  CHECK((n - r.col(0)).norm() < 1e-14);
  CHECK((b.gradient(world(y)) - r.col(0)).norm() < 1e-14);
  CHECK_THAT(b.normal_cone_cosine(world(y), r.col(0)), WithinAbs(1.0, 1e-14));
  CHECK_THAT(b.normal_cone_cosine(world(y), Vec<Dim>((r.col(0) + r.col(1)).normalized())),
             WithinAbs(std::sqrt(0.5), 1e-14));
  // a corner: no single face; the gradient is the bisector, every outward direction of the
  // octant fits the cone exactly, an inward one not at all
  const Vec<Dim> corner = world(h);
  CHECK_FALSE(b.box_face_normal(corner, &n));
  CHECK((b.gradient(corner) - r * Vec<Dim>::Ones().normalized()).norm() < 1e-12);
  CHECK_THAT(b.normal_cone_cosine(corner, r.col(0)), WithinAbs(1.0, 1e-12));
  CHECK_THAT(b.normal_cone_cosine(corner, Vec<Dim>(-r.col(0))), WithinAbs(0.0, 1e-12));
}
