// Tests of the contact problem (reference/contact/contact_system.hpp): the Jacobians against finite
// differences of body motion, the definiteness of A33/A44, the right-hand side b3 of eq. (16),
// restitution per pair, and the staggered projections against a dense oracle of eq. (15).
#include <catch2/catch.hpp>

#include <random>

#include <Eigen/Dense>

#include "reference/app/scene_file.hpp"
#include "reference/contact/collision.hpp"
#include "reference/contact/contact_system.hpp"
#include "reference/rigid/rigid_body.hpp"
#include "reference/rigid/rigid_world.hpp"

using namespace monolith;
using nlohmann::json;

namespace {

/// A scene of `dim` with the given bodies JSON (unit domain, 32 cells, walls everywhere).
SceneDesc scene_with(int dim, const json& bodies, double wall_friction = 0.0,
                     double wall_restitution = 0.0) {
  json j = {{"format", "monolith-scene/1"}, {"name", "t"}, {"dim", dim}};
  j["domain"] = {{"lower", dim == 2 ? json{0, 0} : json{0, 0, 0}},
                 {"upper", dim == 2 ? json{1, 1} : json{1, 1, 1}},
                 {"cells", dim == 2 ? json{32, 32} : json{32, 32, 32}},
                 {"wall_friction", wall_friction},
                 {"wall_restitution", wall_restitution}};
  j["bodies"] = bodies;
  return parse_scene(j, "test", ".");
}

template <int Dim>
json vec_json(const Vec<Dim>& v) {
  json a = json::array();
  for (int i = 0; i < Dim; ++i) a.push_back(v[i]);
  return a;
}

/// Three dynamic bodies (two boxes, a ball) and one kinematic box, random velocities.
template <int Dim>
std::vector<RigidBody<Dim>> random_bodies(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  json bodies = json::array();
  auto c = [&](double x, double y) {
    Vec<Dim> p = Vec<Dim>::Constant(0.5);
    p[0] = x;
    p[1] = y;
    return vec_json<Dim>(p);
  };
  json rot = Dim == 2 ? json(0.3) : json{0.1, 0.2, 0.3};
  bodies.push_back({{"name", "a"}, {"density", 500}, {"friction", 0.4}, {"restitution", 0.2},
                    {"shape", {{"type", "box"}, {"center", c(0.3, 0.3)},
                               {"half_size", vec_json<Dim>(Vec<Dim>::Constant(0.08))},
                               {"rotation", rot}}}});
  bodies.push_back({{"name", "b"}, {"density", 800}, {"friction", 0.9}, {"restitution", 0.6},
                    {"shape", {{"type", "sphere"}, {"center", c(0.6, 0.4)}, {"radius", 0.1}}}});
  bodies.push_back({{"name", "k"}, {"motion", "kinematic"}, {"density", 500},
                    {"path", {{"type", "oscillate"}, {"axis", c(1.0, 0.0)}, {"amplitude", 0.05}, {"frequency", 1.0}}},
                    {"shape", {{"type", "box"}, {"center", c(0.5, 0.7)},
                               {"half_size", vec_json<Dim>(Vec<Dim>::Constant(0.05))}}}});
  Vec<Dim> half = Vec<Dim>::Constant(0.06);
  half[0] = 0.12;
  bodies.push_back({{"name", "d"}, {"density", 300}, {"friction", 0.2},
                    {"shape", {{"type", "box"}, {"center", c(0.7, 0.15)}, {"half_size", vec_json<Dim>(half)}}}});
  std::vector<RigidBody<Dim>> out = make_bodies<Dim>(scene_with(Dim, bodies));
  for (auto& b : out) {
    if (!b.is_dynamic()) {
      b.set_kinematic_state(0.13);
      continue;
    }
    BodyVec<Dim> v;
    for (int i = 0; i < kBodyDofs<Dim>; ++i) v[i] = u(rng);
    b.set_generalized_velocity(v);
  }
  return out;
}

template <int Dim>
Vec<Dim> random_unit(std::mt19937& rng) {
  std::normal_distribution<double> g;
  Vec<Dim> n;
  for (int i = 0; i < Dim; ++i) n[i] = g(rng);
  return n.normalized();
}

/// Random contacts between the bodies of random_bodies (pairs with a dynamic body, and walls).
template <int Dim>
std::vector<Contact<Dim>> random_contacts(const std::vector<RigidBody<Dim>>& bodies, int count,
                                          unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int pairs[6][2] = {{0, 1}, {0, -1}, {1, 2}, {3, 0}, {3, -1}, {1, 3}};
  std::vector<Contact<Dim>> out;
  for (int k = 0; k < count; ++k) {
    Contact<Dim> c;
    c.body_a = pairs[k % 6][0];
    c.body_b = pairs[k % 6][1];
    c.wall_face = c.body_b < 0 ? 2 : -1;
    c.point = bodies[c.body_a].position + 0.08 * Vec<Dim>::NullaryExpr([&](Eigen::Index) { return u(rng); });
    c.normal = random_unit<Dim>(rng);
    c.phi = 0.01 * u(rng);
    c.friction = 0.5;
    c.restitution = 0.0;
    out.push_back(c);
  }
  return out;
}

/// Exact solution of min 1/2 x^T A x - b^T x, x >= 0 (A SPD, n <= 14) by enumerating the free
/// sets: the unique point that satisfies the KKT conditions.
Eigen::VectorXd dense_nonnegative_qp(const Eigen::MatrixXd& a, const Eigen::VectorXd& b) {
  const int n = static_cast<int>(b.size());
  Eigen::VectorXd best;
  double best_violation = std::numeric_limits<double>::infinity();
  for (int mask = 0; mask < (1 << n); ++mask) {
    std::vector<int> free;
    for (int i = 0; i < n; ++i)
      if (mask & (1 << i)) free.push_back(i);
    Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
    if (!free.empty()) {
      Eigen::MatrixXd aff(free.size(), free.size());
      Eigen::VectorXd bf(free.size());
      for (std::size_t i = 0; i < free.size(); ++i) {
        bf[i] = b[free[i]];
        for (std::size_t j = 0; j < free.size(); ++j) aff(i, j) = a(free[i], free[j]);
      }
      const Eigen::VectorXd xf = aff.ldlt().solve(bf);
      for (std::size_t i = 0; i < free.size(); ++i) x[free[i]] = xf[i];
    }
    // KKT violation: x >= 0, gradient >= 0, complementarity
    const Eigen::VectorXd g = a * x - b;
    double v = 0.0;
    for (int i = 0; i < n; ++i) v = std::max({v, -x[i], -g[i], std::abs(x[i] * g[i])});
    if (v < best_violation) {
      best_violation = v;
      best = x;
    }
  }
  return best;
}

template <int Dim>
ContactParameters test_parameters() {
  ContactParameters p;
  p.dt = 0.01;
  p.dx = 1.0 / 32.0;
  p.baumgarte = 0.2;
  p.margin_cells = 0.1;
  p.restitution_threshold = 2.0 * 9.81 * p.dt;
  return p;
}

/// A sphere of radius 0.1 (density 500) centred at (0.5, 0.1[, 0.5]) and its contact with the
/// floor (wall face 2, normal +y, at the sphere's lowest point); the caller sets phi and the
/// body's velocity.
template <int Dim>
std::pair<std::vector<RigidBody<Dim>>, Contact<Dim>> sphere_on_floor() {
  Vec<Dim> c = Vec<Dim>::Constant(0.5);
  c[1] = 0.1;
  json bodies = json::array();
  bodies.push_back({{"density", 500}, {"shape", {{"type", "sphere"}, {"center", vec_json<Dim>(c)}, {"radius", 0.1}}}});
  Contact<Dim> k;
  k.body_a = 0;
  k.body_b = -1;
  k.wall_face = 2;
  k.normal = Vec<Dim>::Unit(1);
  k.point = c - 0.1 * Vec<Dim>::Unit(1);
  return {make_bodies<Dim>(scene_with(Dim, bodies)), k};
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("J_lambda and J_z rows are the relative contact velocities (finite differences of positions)",
                       "[unit][property]", ((int Dim), Dim), 2, 3) {
  for (unsigned seed = 1; seed <= 3; ++seed) {
    std::vector<RigidBody<Dim>> bodies = random_bodies<Dim>(seed);
    const std::vector<Contact<Dim>> contacts = random_contacts<Dim>(bodies, 12, seed + 10);
    const ContactSystem<Dim> sys(bodies, contacts, test_parameters<Dim>());
    REQUIRE(sys.num_contacts() == 12);
    REQUIRE(sys.num_body_dofs() == 3 * kBodyDofs<Dim>);
    const VectorX un = sys.normal_velocity(sys.v_star);
    const VectorX ut = sys.tangent_velocity(sys.v_star);
    // material points at each contact point, moved by the bodies' own time integration
    const double h = 1e-7, t0 = 0.13;
    std::vector<RigidBody<Dim>> moved = bodies;
    for (auto& b : moved) b.integrate(h, t0 + h);
    for (int c = 0; c < sys.num_contacts(); ++c) {
      const Contact<Dim>& k = contacts[c];
      auto displacement = [&](int bi) -> Vec<Dim> {
        if (bi < 0) return Vec<Dim>::Zero();
        const Vec<Dim> rest = bodies[bi].to_rest(k.point);
        return moved[bi].to_world(rest) - k.point;
      };
      const Vec<Dim> rel = (displacement(k.body_a) - displacement(k.body_b)) / h;
      CAPTURE(seed, c, k.body_a, k.body_b);
      CHECK(un[c] == Approx(k.normal.dot(rel)).margin(1e-5));
      for (int j = 0; j < Dim - 1; ++j) {
        const Vec<Dim>& t = sys.tangents[(Dim - 1) * c + j];
        // tangents: unit, orthogonal to the normal and to each other
        CHECK(t.norm() == Approx(1.0).margin(1e-14));
        CHECK(std::abs(t.dot(k.normal)) < 1e-14);
        if (j > 0) CHECK(std::abs(t.dot(sys.tangents[(Dim - 1) * c])) < 1e-14);
        CHECK(ut[(Dim - 1) * c + j] == Approx(t.dot(rel)).margin(1e-5));
      }
    }
  }
}

TEMPLATE_TEST_CASE_SIG("A33 and A44 of eq. (24) are symmetric positive semi-definite, M_r M_r^-1 = I",
                       "[unit][property]", ((int Dim), Dim), 2, 3) {
  const std::vector<RigidBody<Dim>> bodies = random_bodies<Dim>(4);
  // more contacts than DOFs: A33 is singular, yet never indefinite
  const std::vector<Contact<Dim>> contacts = random_contacts<Dim>(bodies, 24, 7);
  const ContactSystem<Dim> sys(bodies, contacts, test_parameters<Dim>());
  const Eigen::MatrixXd mm = Eigen::MatrixXd(sys.m_r) * Eigen::MatrixXd(sys.m_r_inverse);
  CHECK((mm - Eigen::MatrixXd::Identity(mm.rows(), mm.cols())).norm() < 1e-10);
  const Eigen::MatrixXd a33 = Eigen::MatrixXd(sys.a33());
  const Eigen::MatrixXd a44 = Eigen::MatrixXd(sys.a44());
  const Eigen::MatrixXd a34 = Eigen::MatrixXd(sys.a34());
  REQUIRE(a33.rows() == 24);
  REQUIRE(a44.rows() == 24 * (Dim - 1));
  REQUIRE(a34.cols() == 24 * (Dim - 1));
  // the whole contact block [A33 A34; A34^T A44]
  Eigen::MatrixXd full(a33.rows() + a44.rows(), a33.rows() + a44.rows());
  full << a33, a34, a34.transpose(), a44;
  for (const Eigen::MatrixXd* m : std::vector<const Eigen::MatrixXd*>{&a33, &a44, &full}) {
    CHECK((*m - m->transpose()).norm() <= 1e-12 * m->norm());
    const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(*m).eigenvalues();
    CHECK(ev.minCoeff() >= -1e-12 * ev.maxCoeff());
    // rank at most the number of DOFs
    int positive = 0;
    for (int i = 0; i < ev.size(); ++i) positive += ev[i] > 1e-10 * ev.maxCoeff();
    CHECK(positive <= sys.num_body_dofs());
  }
  // explicitly dt alpha J M^-1 J^T with alpha = 1/dx^Dim
  const double alpha = std::pow(32.0, Dim);
  const Eigen::MatrixXd j = Eigen::MatrixXd(sys.j_lambda);
  CHECK((a33 - 0.01 * alpha * j * Eigen::MatrixXd(sys.m_r_inverse) * j.transpose()).norm() <= 1e-10 * a33.norm());
}

TEMPLATE_TEST_CASE_SIG("b3 of eq. (16): zero at rest at phi = -epsilon, negative when separating, Baumgarte when deeper",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  auto setup = sphere_on_floor<Dim>();
  std::vector<RigidBody<Dim>>& b = setup.first;
  Contact<Dim>& k = setup.second;
  const ContactParameters p = test_parameters<Dim>();
  const double eps = p.margin_cells * p.dx;
  // resting: zero velocity, phi = -epsilon
  b[0].velocity.setZero();
  k.phi = -eps;
  CHECK(ContactSystem<Dim>(b, {k}, p).b3()[0] == 0.0);
  // separating: b3 < 0 and the solve gives lambda = 0 and keeps v*
  b[0].velocity = 0.3 * Vec<Dim>::Unit(1);
  {
    const ContactSystem<Dim> sys(b, {k}, p);
    CHECK(sys.b3()[0] < 0.0);
    const StaggeredResult r = solve_staggered_projections<Dim>(sys, StaggeredSettings{});
    CHECK(r.lambda[0] == 0.0);
    CHECK((sys.velocity_update(r.lambda, r.z) - sys.v_star).norm() == 0.0);
  }
  // penetrating beyond the margin at rest: the solve pushes out at beta (-phi - eps) / dt
  b[0].velocity.setZero();
  k.phi = -eps - 0.004;
  {
    const ContactSystem<Dim> sys(b, {k}, p);
    CHECK(sys.b3()[0] == Approx(sys.alpha * p.baumgarte * 0.004 / p.dt));
    const StaggeredResult r = solve_staggered_projections<Dim>(sys, StaggeredSettings{});
    const VectorX v = sys.velocity_update(r.lambda, r.z);
    CHECK(v[1] == Approx(p.baumgarte * 0.004 / p.dt).epsilon(1e-3));
  }
  // a gap ahead (speculative contact): the body may close it within the step but not more
  b[0].velocity = -2.0 * Vec<Dim>::Unit(1);
  k.phi = 0.005;
  {
    ContactParameters q = p;
    q.restitution_threshold = 1e9;  // no bounce here
    const ContactSystem<Dim> sys(b, {k}, q);
    const StaggeredResult r = solve_staggered_projections<Dim>(sys, StaggeredSettings{});
    const VectorX v = sys.velocity_update(r.lambda, r.z);
    CHECK(v[1] == Approx(-(0.005 + eps) / p.dt).epsilon(1e-3));
  }
}

TEMPLATE_TEST_CASE_SIG("eq. (16) with the recovery cap: the push-out speed stops growing as dt shrinks",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  auto setup = sphere_on_floor<Dim>();
  std::vector<RigidBody<Dim>>& b = setup.first;
  Contact<Dim>& k = setup.second;
  b[0].velocity.setZero();
  const ContactParameters p = test_parameters<Dim>();
  const double eps = p.margin_cells * p.dx;
  k.phi = -eps - 0.004;  // 4 mm beyond the margin, at rest
  // the speed after the solve of the contact alone (the push-out speed of eq. (16))
  auto push_out = [&](const ContactParameters& q) {
    const ContactSystem<Dim> sys(b, {k}, q);
    const StaggeredResult r = solve_staggered_projections<Dim>(sys, StaggeredSettings{});
    return sys.velocity_update(r.lambda, r.z)[1];
  };
  // the cap of RigidWorldSettings::from_scene's rule: a one-cell penetration at dt = 0.01
  ContactParameters capped = p;
  capped.max_recovery_speed = p.baumgarte * p.dx / 0.01;
  // at the largest step the penetration (below one cell) is pushed out at beta phi / dt, capped
  // or not: the cap changes nothing there (b3 bit for bit)
  CHECK(ContactSystem<Dim>(b, {k}, capped).b3()[0] == ContactSystem<Dim>(b, {k}, p).b3()[0]);
  CHECK(push_out(capped) == Approx(p.baumgarte * 0.004 / p.dt).epsilon(1e-3));
  // dt 100x shorter: uncapped, the push-out speed is 100x faster; capped, it is the cap
  for (double scale : {0.1, 0.01, 1e-4}) {
    ContactParameters q = p, qc = capped;
    q.dt = qc.dt = scale * p.dt;
    q.restitution_threshold = qc.restitution_threshold = 2.0 * 9.81 * q.dt;
    INFO("dt = " << q.dt);
    CHECK(push_out(q) == Approx(p.baumgarte * 0.004 / q.dt).epsilon(1e-3));
    CHECK(push_out(qc) == Approx(capped.max_recovery_speed).epsilon(1e-3));
    CHECK(push_out(qc) < push_out(q));
  }
  // the cap acts on the Baumgarte part only: an approaching contact above the restitution
  // threshold still bounces at e u*, plus at most the cap
  b[0].velocity = -1.0 * Vec<Dim>::Unit(1);
  k.restitution = 0.5;
  ContactParameters q = capped;
  q.dt = 1e-4;
  q.restitution_threshold = 2.0 * 9.81 * q.dt;
  const ContactSystem<Dim> sys(b, {k}, q);
  REQUIRE(sys.restitution_scale[0] == Approx(1.5));
  const VectorX un = sys.normal_velocity(sys.v_star);
  CHECK(sys.b3()[0] / sys.alpha == Approx(-un[0] - 0.5 * un[0] + capped.max_recovery_speed));
}

TEST_CASE("the recovery cap of a scene: solver.max_recovery_speed, or beta dx / the largest step",
          "[unit]") {
  SceneDesc s = scene_with(3, json::array());
  s.time.max_dt = 0.01;
  s.time.fps = 50.0;
  s.solver.baumgarte = 0.2;
  // dx = 1/32: 0.2 / 32 / 0.01
  CHECK(RigidWorldSettings::from_scene(s).max_recovery_speed == Approx(0.625));
  // frames shorter than max_dt: the frame is the largest step
  s.time.fps = 200.0;
  CHECK(RigidWorldSettings::from_scene(s).max_recovery_speed == Approx(0.2 / 32.0 / 0.005));
  s.solver.max_recovery_speed = 3.0;
  CHECK(RigidWorldSettings::from_scene(s).max_recovery_speed == 3.0);
  // the world hands it to the contact system
  const RigidWorld<3> world(s);
  CHECK(world.contact_parameters(0.001, Vec<3>(0.0, -9.81, 0.0)).max_recovery_speed == 3.0);
}

TEMPLATE_TEST_CASE_SIG("restitution: per contact row, max over the pair, only above the threshold",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // two balls of restitution 0.2 and 0.7 touching: detect_contacts combines max(e_a, e_b)
  Vec<Dim> c1 = Vec<Dim>::Constant(0.5), c2 = Vec<Dim>::Constant(0.5);
  c1[0] = 0.4;
  c2[0] = 0.6 - 0.002;
  json bodies = json::array();
  bodies.push_back({{"density", 500}, {"restitution", 0.2}, {"shape", {{"type", "sphere"}, {"center", vec_json<Dim>(c1)}, {"radius", 0.1}}}});
  bodies.push_back({{"density", 500}, {"restitution", 0.7}, {"shape", {{"type", "sphere"}, {"center", vec_json<Dim>(c2)}, {"radius", 0.1}}}});
  std::vector<RigidBody<Dim>> b = make_bodies<Dim>(scene_with(Dim, bodies, 0.0, 0.0));
  b[0].velocity = 1.5 * Vec<Dim>::Unit(0);
  b[1].velocity = -1.5 * Vec<Dim>::Unit(0);
  const std::vector<Contact<Dim>> contacts = detect_contacts<Dim>(b, Walls<Dim>(), 0.01);
  REQUIRE(contacts.size() == 1);
  CHECK(contacts[0].restitution == 0.7);
  const ContactParameters p = test_parameters<Dim>();
  const ContactSystem<Dim> sys(b, contacts, p);
  CHECK(sys.restitution_scale[0] == Approx(1.7));
  const StaggeredResult r = solve_staggered_projections<Dim>(sys, StaggeredSettings{});
  const VectorX v = sys.velocity_update(r.lambda, r.z);
  // equal masses, head-on: the approach speed 3 m/s comes back as 0.7 x 3 m/s of separation;
  // exactly: the (1 + gamma) boost of section 4.4.5 scales the impulse (1 + e) 3 by 1/(1 + gamma)
  const double gamma = StaggeredSettings{}.diagonal_boost;
  CHECK(sys.normal_velocity(v)[0] == Approx(-3.0 + 1.7 * 3.0 / (1.0 + gamma)).epsilon(1e-8));
  CHECK(sys.normal_velocity(v)[0] == Approx(0.7 * 3.0).epsilon(1e-3));
  // momentum is conserved by the pair force
  CHECK((v.template segment<Dim>(0) + v.template segment<Dim>(kBodyDofs<Dim>)).norm() < 1e-9);
  // slower than the threshold (a resting contact): no bounce
  b[0].velocity = 0.5 * p.restitution_threshold * Vec<Dim>::Unit(0);
  b[1].velocity.setZero();
  CHECK(ContactSystem<Dim>(b, contacts, p).restitution_scale[0] == 1.0);
}

TEMPLATE_TEST_CASE_SIG("staggered projections with mu = 0 match a dense oracle of eq. (15)",
                       "[unit][dense-reference]", ((int Dim), Dim), 2, 3) {
  for (unsigned seed = 1; seed <= 4; ++seed) {
    const std::vector<RigidBody<Dim>> bodies = random_bodies<Dim>(seed);
    std::vector<Contact<Dim>> contacts = random_contacts<Dim>(bodies, 10, 100 + seed);
    for (auto& c : contacts) c.friction = 0.0;
    const ContactSystem<Dim> sys(bodies, contacts, test_parameters<Dim>());
    StaggeredSettings s;
    s.mprgp.tolerance = 1e-12;
    s.diagonal_boost = 1e-4;
    const StaggeredResult r = solve_staggered_projections<Dim>(sys, s);
    CHECK(r.staggered_iterations == 1);
    CHECK(r.converged);
    // the oracle: the same boosted QP solved exactly by enumeration
    Eigen::MatrixXd a = Eigen::MatrixXd(sys.a33());
    a.diagonal() *= 1.0 + s.diagonal_boost;
    const Eigen::VectorXd exact = dense_nonnegative_qp(a, sys.b3());
    CAPTURE(seed);
    CHECK((r.lambda - exact).template lpNorm<Eigen::Infinity>() <= 1e-8 * std::max(1.0, exact.lpNorm<Eigen::Infinity>()));
    // Signorini for the boosted problem MPRGP solves: lambda >= 0, w = (A33 + gamma diag) lambda
    // - b3 >= 0, lambda_i w_i = 0
    const Eigen::VectorXd w = a * r.lambda - sys.b3();
    const double bscale = sys.b3().template lpNorm<Eigen::Infinity>();
    CHECK(r.lambda.minCoeff() >= 0.0);
    CHECK(w.minCoeff() >= -1e-9 * bscale);
    for (int c = 0; c < sys.num_contacts(); ++c) CHECK(std::abs(w[c]) * r.lambda[c] <= 1e-9 * bscale * std::max(1.0, exact.template lpNorm<Eigen::Infinity>()));
    // with a negligible boost the velocities are those of the unboosted eq. (15) (unique even
    // where A33 is singular, as with 10 contacts on 9 DOFs in 2D)
    StaggeredSettings tiny = s;
    tiny.diagonal_boost = 1e-9;
    const StaggeredResult r0 = solve_staggered_projections<Dim>(sys, tiny);
    Eigen::MatrixXd a0 = Eigen::MatrixXd(sys.a33());
    a0.diagonal() *= 1.0 + 1e-12;
    const Eigen::VectorXd exact0 = dense_nonnegative_qp(a0, sys.b3());
    const VectorX v = sys.velocity_update(r0.lambda, r0.z);
    const VectorX v0 = sys.velocity_update(exact0, VectorX::Zero(sys.num_friction_rows()));
    CHECK((v - v0).norm() <= 1e-5 * std::max(1.0, v0.norm()));
  }
}

TEMPLATE_TEST_CASE_SIG("staggered projections with mu > 0 satisfy the pyramid bounds and the Signorini conditions",
                       "[unit][property]", ((int Dim), Dim), 2, 3) {
  for (unsigned seed = 1; seed <= 3; ++seed) {
    const std::vector<RigidBody<Dim>> bodies = random_bodies<Dim>(seed);
    const std::vector<Contact<Dim>> contacts = random_contacts<Dim>(bodies, 10, 200 + seed);
    const ContactSystem<Dim> sys(bodies, contacts, test_parameters<Dim>());
    StaggeredSettings s;
    s.max_iterations = 50;
    s.tolerance = 1e-8;
    s.mprgp.tolerance = 1e-10;
    const StaggeredResult r = solve_staggered_projections<Dim>(sys, s);
    CAPTURE(seed, r.staggered_iterations, r.last_change);
    CHECK(r.staggered_iterations >= 2);
    CHECK(r.lambda.minCoeff() >= 0.0);
    const double scale = std::max(1e-12, r.lambda.template lpNorm<Eigen::Infinity>());
    for (int c = 0; c < sys.num_contacts(); ++c)
      for (int j = 0; j < Dim - 1; ++j)
        // z was bounded by mu lambda^k, and the final normal solve moved lambda by at most
        // last_change ||lambda||_inf: the pyramid holds to the staggered tolerance
        CHECK(std::abs(r.z[(Dim - 1) * c + j]) <=
              sys.mu[c] * (r.lambda[c] + r.last_change * scale) + 1e-9 * scale);
    // the final normal solve is exact for the final friction (on the boosted A33 it solves)
    Eigen::MatrixXd a = Eigen::MatrixXd(sys.a33());
    a.diagonal() *= 1.0 + s.diagonal_boost;
    const Eigen::VectorXd w = a * r.lambda + Eigen::MatrixXd(sys.a34()) * r.z - sys.b3();
    const double bscale = sys.b3().template lpNorm<Eigen::Infinity>();
    CHECK(w.minCoeff() >= -1e-6 * bscale);
    for (int c = 0; c < sys.num_contacts(); ++c) CHECK(std::abs(w[c] * r.lambda[c]) <= 1e-6 * bscale * scale);
    // maximal dissipation: each friction row opposes the slip it leaves, z_i (J_z v + g_t)_i <= 0
    const VectorX v = sys.velocity_update(r.lambda, r.z);
    const VectorX slip = sys.tangent_velocity(v);
    for (int i = 0; i < sys.num_friction_rows(); ++i)
      CHECK(r.z[i] * slip[i] <= 1e-6 * scale * std::max(1.0, slip.template lpNorm<Eigen::Infinity>()));
  }
}

TEMPLATE_TEST_CASE_SIG("friction on a sliding box opposes the slip and stops at mu lambda",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // a box at rest on the floor (phi = -epsilon) sliding along x: every contact's friction row
  // along x is at -mu lambda, and the box decelerates by mu g dt in one step
  Vec<Dim> c = Vec<Dim>::Constant(0.5), h = Vec<Dim>::Constant(0.05);
  c[1] = 0.05;
  json bodies = json::array();
  bodies.push_back({{"density", 500}, {"friction", 0.5}, {"shape", {{"type", "box"}, {"center", vec_json<Dim>(c)}, {"half_size", vec_json<Dim>(h)}}}});
  std::vector<RigidBody<Dim>> b = make_bodies<Dim>(scene_with(Dim, bodies, 0.5));
  const ContactParameters p = test_parameters<Dim>();
  const double g = 9.81;
  b[0].velocity = 1.0 * Vec<Dim>::Unit(0) - g * p.dt * Vec<Dim>::Unit(1);
  Walls<Dim> walls = Walls<Dim>::from_scene(scene_with(Dim, bodies, 0.5));
  std::vector<Contact<Dim>> contacts = detect_contacts<Dim>(b, walls, 0.01);
  REQUIRE(contacts.size() == (Dim == 2 ? 2u : 4u));
  for (auto& k : contacts) k.phi = -p.margin_cells * p.dx;
  const ContactSystem<Dim> sys(b, contacts, p);
  StaggeredSettings s;
  s.max_iterations = 20;
  s.tolerance = 1e-10;
  s.mprgp.tolerance = 1e-12;
  const StaggeredResult r = solve_staggered_projections<Dim>(sys, s);
  const VectorX v = sys.velocity_update(r.lambda, r.z);
  // normal: the weight; tangential: mu times it, against the motion
  CHECK(r.lambda.sum() == Approx(b[0].mass * g).epsilon(1e-3));
  CHECK(v[0] == Approx(1.0 - 0.5 * g * p.dt).epsilon(1e-3));
  CHECK(std::abs(v[1]) < 1e-3);
}
