// Copyright 2026 The tactfunc Authors.
//
// SE2: group axioms, Exp/Log round trips, angle wrapping, small-angle stability, and
// every analytic Jacobian checked against ceres::Jet autodiff and against central
// finite differences at the identity, at tiny inputs (theta ~ 1e-12) and at random
// ones. A Jacobian of a group-valued output is the right Jacobian
// d Log(out(x)^-1 out(x (+) d)) / d d at d = 0, the convention the header documents.
//
// Tolerances: Jet autodiff is exact up to rounding, so analytic vs Jet must agree to
// 1e-12 (relative to max(1, |J|)). Central differences with h = 1e-6 carry
// O(h^2) ~ 1e-12 truncation and eps/h ~ 1e-10 rounding error: 1e-8.
#include "models/core/se2.h"

#include <boost/random/mersenne_twister.hpp>
#include <boost/random/uniform_real_distribution.hpp>
#include <cmath>
#include <string>
#include <type_traits>
#include <vector>

#include "Eigen/LU"
#include "ceres/jet.h"
#include "gtest/gtest.h"

namespace tactfunc {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector2d;
using Eigen::Vector3d;
using Jet3 = ceres::Jet<double, 3>;
constexpr double kPi = M_PI;
constexpr double kJetTolerance = 1e-12;
constexpr double kFiniteDifferenceTolerance = 1e-8;
constexpr double kStep = 1e-6;

// Named inputs: identity, tiny, random.
struct PoseCase {
  std::string name;
  SE2d pose;
};
struct TangentCase {
  std::string name;
  Vector3d tau;
};

std::vector<PoseCase> Poses(unsigned seed, double max_angle = 3.0) {
  std::vector<PoseCase> cases = {{"identity", SE2d()},
                                 {"tiny", SE2d::FromXYYaw(1e-9, -2e-9, 1e-12)}};
  boost::random::mt19937_64 rng(seed);
  boost::random::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 5; ++i) {
    cases.push_back(
        {"random" + std::to_string(i), SE2d::FromXYYaw(u(rng), u(rng), max_angle * u(rng))});
  }
  return cases;
}

std::vector<TangentCase> Tangents(unsigned seed) {
  std::vector<TangentCase> cases = {{"zero", Vector3d::Zero()},
                                    {"tiny", Vector3d(1e-9, -2e-9, 1e-12)},
                                    {"small_angle_branch", Vector3d(0.3, -0.2, 0.009)},
                                    {"large_angle_branch", Vector3d(0.3, -0.2, 0.011)}};
  boost::random::mt19937_64 rng(seed);
  boost::random::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 5; ++i) {
    cases.push_back({"random" + std::to_string(i), Vector3d(u(rng), u(rng), 3.0 * u(rng))});
  }
  return cases;
}

template <typename T>
Eigen::Matrix<T, 3, 1> JetDelta() {
  Eigen::Matrix<T, 3, 1> d;
  for (int k = 0; k < 3; ++k) d[k] = T(0.0, k);
  return d;
}

Matrix3d JetDerivative(const Eigen::Matrix<Jet3, 3, 1>& v) {
  Matrix3d j;
  for (int r = 0; r < 3; ++r) j.row(r) = v[r].v.transpose();
  return j;
}

// Right Jacobian of a group-valued f(delta) (delta in R^3, f(0) = nominal output) by
// Jet autodiff and by central differences.
template <typename F>
Matrix3d GroupJacobianByJet(const F& f) {
  const SE2<Jet3> out0 = f(Vector3d::Zero().eval()).template Cast<Jet3>();
  const SE2<Jet3> out = f(JetDelta<Jet3>());
  return JetDerivative((out0.Inverse() * out).Log());
}
template <typename F>
Matrix3d GroupJacobianByDifferences(const F& f) {
  const SE2d out0_inv = f(Vector3d::Zero().eval()).Inverse();
  Matrix3d j;
  for (int k = 0; k < 3; ++k) {
    const Vector3d h = kStep * Vector3d::Unit(k);
    const Vector3d plus = (out0_inv * f(h)).Log();
    const Vector3d minus = (out0_inv * f((-h).eval())).Log();
    j.col(k) = (plus - minus) / (2 * kStep);
  }
  return j;
}
// The same for a vector-valued f (ordinary derivative of the output).
template <typename F>
Eigen::MatrixXd VectorJacobianByJet(const F& f) {
  const auto out = f(JetDelta<Jet3>());
  Eigen::MatrixXd j(out.size(), 3);
  for (int r = 0; r < out.size(); ++r) j.row(r) = out[r].v.transpose();
  return j;
}
template <typename F>
Eigen::MatrixXd VectorJacobianByDifferences(const F& f) {
  const auto out0 = f(Vector3d::Zero().eval());
  Eigen::MatrixXd j(out0.size(), 3);
  for (int k = 0; k < 3; ++k) {
    const Vector3d h = kStep * Vector3d::Unit(k);
    j.col(k) = (f(h) - f((-h).eval())) / (2 * kStep);
  }
  return j;
}

// Scalar type of a delta argument.
template <typename V>
using ScalarOf = typename std::decay_t<V>::Scalar;

void ExpectJacobianNear(const Eigen::MatrixXd& analytic, const Eigen::MatrixXd& reference,
                        double tolerance, const std::string& what) {
  const double scale = std::max(1.0, reference.cwiseAbs().maxCoeff());
  EXPECT_LE((analytic - reference).cwiseAbs().maxCoeff(), tolerance * scale)
      << what << "\nanalytic:\n"
      << analytic << "\nreference:\n"
      << reference;
}

// ---- Values ---------------------------------------------------------------------------

TEST(Se2, DefaultConstructedPoseIsTheIdentity) {
  const SE2d t;
  EXPECT_EQ(t.x(), 0.0);
  EXPECT_EQ(t.y(), 0.0);
  EXPECT_EQ(t.yaw(), 0.0);
  EXPECT_TRUE(t.Matrix().isIdentity(0.0));
}

TEST(Se2, FromXYYawRoundTripsThroughTheAccessors) {
  const SE2d t = SE2d::FromXYYaw(0.01, -0.02, 0.7);
  EXPECT_EQ(t.x(), 0.01);
  EXPECT_EQ(t.y(), -0.02);
  EXPECT_EQ(t.yaw(), 0.7);
}

TEST(Se2, ActMapsPointsFromTheObjectFrameIntoTheSensorFrame) {
  // The object sits at (1, 2) in the sensor frame, turned by 90 deg: its +x axis
  // points along the sensor's +y.
  const SE2d sensor_T_object = SE2d::FromXYYaw(1.0, 2.0, kPi / 2);
  const Vector2d p_sensor = sensor_T_object * Vector2d(1.0, 0.0);
  EXPECT_NEAR(p_sensor.x(), 1.0, 1e-15);
  EXPECT_NEAR(p_sensor.y(), 3.0, 1e-15);
}

TEST(Se2, ComposeAndInverseMatchHomogeneousMatrices) {
  for (const PoseCase& a : Poses(1)) {
    for (const PoseCase& b : Poses(2)) {
      EXPECT_TRUE((a.pose * b.pose).Matrix().isApprox(a.pose.Matrix() * b.pose.Matrix(), 1e-14))
          << a.name << " * " << b.name;
    }
    EXPECT_LE((a.pose.Inverse().Matrix() - a.pose.Matrix().inverse()).cwiseAbs().maxCoeff(), 1e-14)
        << a.name;
    const Vector2d p(0.3, -0.4);
    EXPECT_LE((a.pose * p - (a.pose.Matrix() * Vector3d(p.x(), p.y(), 1.0)).head<2>()).norm(),
              1e-15);
  }
}

TEST(Se2, GroupAxiomsHold) {
  const auto poses = Poses(3);
  for (const PoseCase& a : poses) {
    EXPECT_TRUE((a.pose * SE2d()).IsApprox(a.pose, 0.0)) << a.name;
    EXPECT_TRUE((SE2d() * a.pose).IsApprox(a.pose, 0.0)) << a.name;
    EXPECT_TRUE((a.pose * a.pose.Inverse()).IsApprox(SE2d(), 1e-15)) << a.name;
    EXPECT_TRUE((a.pose.Inverse() * a.pose).IsApprox(SE2d(), 1e-15)) << a.name;
    EXPECT_TRUE(a.pose.Inverse().Inverse().IsApprox(a.pose, 1e-15)) << a.name;
    for (const PoseCase& b : poses) {
      for (const PoseCase& c : poses) {
        EXPECT_TRUE(((a.pose * b.pose) * c.pose).IsApprox(a.pose * (b.pose * c.pose), 1e-14))
            << a.name << ", " << b.name << ", " << c.name;
      }
      EXPECT_TRUE(SE2d::Between(a.pose, b.pose).IsApprox(a.pose.Inverse() * b.pose, 0.0));
    }
  }
}

TEST(Se2, LogOfExpIsIdentity) {
  for (const TangentCase& c : Tangents(4)) {
    const Vector3d back = SE2d::Exp(c.tau).Log();
    EXPECT_LE((back - c.tau).cwiseAbs().maxCoeff(), 1e-14 * std::max(1.0, c.tau.norm()))
        << c.name << ": " << back.transpose() << " vs " << c.tau.transpose();
  }
}

TEST(Se2, ExpOfLogIsIdentity) {
  std::vector<PoseCase> cases = Poses(5, kPi);
  cases.push_back({"half_turn", SE2d::FromXYYaw(0.2, -0.1, kPi)});
  cases.push_back({"almost_minus_half_turn", SE2d::FromXYYaw(0.2, -0.1, -kPi + 1e-9)});
  for (const PoseCase& c : cases) {
    EXPECT_TRUE(SE2d::Exp(c.pose.Log()).IsApprox(c.pose, 1e-14))
        << c.name << ": " << SE2d::Exp(c.pose.Log()) << " vs " << c.pose;
  }
}

TEST(Se2, ExpOfPureTranslationIsThatTranslation) {
  const SE2d t = SE2d::Exp(Vector3d(0.3, -0.7, 0.0));
  EXPECT_EQ(t.x(), 0.3);
  EXPECT_EQ(t.y(), -0.7);
  EXPECT_EQ(t.yaw(), 0.0);
}

TEST(Se2, ExpOfQuarterTurnFollowsTheArc) {
  // Moving 1 along x while turning 90 deg traces a quarter circle of radius 2/pi.
  const SE2d t = SE2d::Exp(Vector3d(1.0, 0.0, kPi / 2));
  EXPECT_NEAR(t.x(), 2 / kPi, 1e-15);
  EXPECT_NEAR(t.y(), 2 / kPi, 1e-15);
  EXPECT_NEAR(t.yaw(), kPi / 2, 1e-15);
}

TEST(Se2, AdjointMovesARightPerturbationToTheLeft) {
  for (const PoseCase& c : Poses(6)) {
    const Vector3d tau(0.1, -0.2, 0.3);
    EXPECT_TRUE(
        (c.pose * SE2d::Exp(tau)).IsApprox(SE2d::Exp(c.pose.Adjoint() * tau) * c.pose, 1e-14))
        << c.name;
  }
}

TEST(Se2, SmallAnglesAreStableDownTo1e12) {
  for (double theta : {1e-12, -1e-12, 1e-8, 0.0}) {
    const Vector3d tau(0.25, -0.5, theta);
    const SE2d t = SE2d::Exp(tau);
    // Exact to first order: V(theta) ~= [1 -theta/2; theta/2 1].
    EXPECT_NEAR(t.x(), 0.25 + 0.25 * theta, 1e-16) << theta;
    EXPECT_NEAR(t.y(), -0.5 + 0.125 * theta, 1e-16) << theta;
    EXPECT_EQ(t.yaw(), theta);
    const Vector3d back = t.Log();
    EXPECT_NEAR(back[0], tau[0], 1e-16);
    EXPECT_NEAR(back[1], tau[1], 1e-16);
    EXPECT_EQ(back[2], theta);
    // Jet derivatives through the Taylor branch are finite and match theta = 0's.
    const Matrix3d j = JetDerivative(SE2<Jet3>::Exp(tau.cast<Jet3>() + JetDelta<Jet3>()).Log());
    EXPECT_TRUE(j.allFinite());
    EXPECT_LE((j - Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-15) << j;
  }
}

TEST(Se2, AnglesWrapIntoMinusPiPi) {
  EXPECT_EQ(SE2d::Rot(kPi).yaw(), kPi);
  EXPECT_EQ(SE2d::Rot(-kPi).yaw(), kPi);  // -pi is the same rotation; kept as +pi
  EXPECT_NEAR(SE2d::Rot(3 * kPi).yaw(), kPi, 1e-15);
  EXPECT_NEAR(SE2d::Rot(2 * kPi + 0.25).yaw(), 0.25, 1e-15);
  EXPECT_NEAR(SE2d::Rot(-2 * kPi - 0.25).yaw(), -0.25, 1e-15);
  EXPECT_NEAR(SE2d::Rot(1e10).yaw(), std::remainder(1e10, 2 * kPi), 1e-6);
  // Composition wraps: 3 + 3 rad = 6 - 2 pi.
  EXPECT_NEAR((SE2d::Rot(3.0) * SE2d::Rot(3.0)).yaw(), 6.0 - 2 * kPi, 1e-15);
  // Angles in range pass through bit-exactly.
  EXPECT_EQ(SE2d::NormalizeAngle(0.123456789), 0.123456789);
  // Wrapping keeps the Jet derivative (d wrapped / d angle = 1).
  const Jet3 wrapped = SE2<Jet3>::NormalizeAngle(Jet3(4.0, 0));
  EXPECT_NEAR(wrapped.a, 4.0 - 2 * kPi, 1e-15);
  EXPECT_NEAR(wrapped.v[0], 1.0, 1e-15);
  // NaN stays NaN.
  EXPECT_TRUE(std::isnan(SE2d::NormalizeAngle(std::nan(""))));
}

TEST(Se2, CastConvertsBetweenScalarTypes) {
  const SE2d t = SE2d::FromXYYaw(0.1, 0.2, -0.3);
  const SE2f f = t.Cast<float>();
  EXPECT_EQ(f.x(), 0.1f);
  EXPECT_EQ(f.yaw(), -0.3f);
  const SE2<Jet3> j = t.Cast<Jet3>();
  EXPECT_EQ(j.y().a, 0.2);
  EXPECT_TRUE(j.y().v.isZero());
  // float Exp/Log round trip is accurate to float precision, including small angles.
  for (float theta : {0.0f, 1e-6f, 0.05f, 2.0f}) {
    const Eigen::Vector3f tau(0.3f, -0.2f, theta);
    EXPECT_LE((SE2f::Exp(tau).Log() - tau).cwiseAbs().maxCoeff(), 1e-6f) << theta;
  }
}

// ---- Jacobians -------------------------------------------------------------------------

TEST(Se2, ExpJacobianMatchesJetAndFiniteDifferences) {
  for (const TangentCase& c : Tangents(7)) {
    Matrix3d analytic;
    SE2d::Exp(c.tau, &analytic);
    auto f = [&](const auto& d) {
      using T = ScalarOf<decltype(d)>;
      return SE2<T>::Exp(c.tau.cast<T>() + d);
    };
    ExpectJacobianNear(analytic, GroupJacobianByJet(f), kJetTolerance, "Exp jet " + c.name);
    ExpectJacobianNear(analytic, GroupJacobianByDifferences(f), kFiniteDifferenceTolerance,
                       "Exp fd " + c.name);
  }
}

TEST(Se2, LogJacobianMatchesJetAndFiniteDifferences) {
  for (const PoseCase& c : Poses(8)) {
    Matrix3d analytic;
    c.pose.Log(&analytic);
    auto f = [&](const auto& d) {
      using T = ScalarOf<decltype(d)>;
      return (c.pose.Cast<T>() * SE2<T>::Exp(d)).Log();
    };
    ExpectJacobianNear(analytic, VectorJacobianByJet(f), kJetTolerance, "Log jet " + c.name);
    ExpectJacobianNear(analytic, VectorJacobianByDifferences(f), kFiniteDifferenceTolerance,
                       "Log fd " + c.name);
  }
}

TEST(Se2, InverseJacobianMatchesJetAndFiniteDifferences) {
  for (const PoseCase& c : Poses(9)) {
    Matrix3d analytic;
    c.pose.Inverse(&analytic);
    auto f = [&](const auto& d) {
      using T = ScalarOf<decltype(d)>;
      return (c.pose.Cast<T>() * SE2<T>::Exp(d)).Inverse();
    };
    ExpectJacobianNear(analytic, GroupJacobianByJet(f), kJetTolerance, "Inverse jet " + c.name);
    ExpectJacobianNear(analytic, GroupJacobianByDifferences(f), kFiniteDifferenceTolerance,
                       "Inverse fd " + c.name);
  }
}

TEST(Se2, ComposeAndBetweenJacobiansMatchJetAndFiniteDifferences) {
  const auto as = Poses(10);
  const auto bs = Poses(11);
  for (std::size_t i = 0; i < as.size(); ++i) {
    const SE2d& a = as[i].pose;
    const SE2d& b = bs[i].pose;
    const std::string name = as[i].name;
    Matrix3d J_ab_a, J_ab_b, J_between_a, J_between_b;
    SE2d::Compose(a, b, &J_ab_a, &J_ab_b);
    SE2d::Between(a, b, &J_between_a, &J_between_b);
    auto compose_a = [&](const auto& d) {
      using T = ScalarOf<decltype(d)>;
      return SE2<T>::Compose(a.Cast<T>() * SE2<T>::Exp(d), b.Cast<T>());
    };
    auto compose_b = [&](const auto& d) {
      using T = ScalarOf<decltype(d)>;
      return SE2<T>::Compose(a.Cast<T>(), b.Cast<T>() * SE2<T>::Exp(d));
    };
    auto between_a = [&](const auto& d) {
      using T = ScalarOf<decltype(d)>;
      return SE2<T>::Between(a.Cast<T>() * SE2<T>::Exp(d), b.Cast<T>());
    };
    auto between_b = [&](const auto& d) {
      using T = ScalarOf<decltype(d)>;
      return SE2<T>::Between(a.Cast<T>(), b.Cast<T>() * SE2<T>::Exp(d));
    };
    ExpectJacobianNear(J_ab_a, GroupJacobianByJet(compose_a), kJetTolerance, "J_ab_a " + name);
    ExpectJacobianNear(J_ab_b, GroupJacobianByJet(compose_b), kJetTolerance, "J_ab_b " + name);
    ExpectJacobianNear(J_between_a, GroupJacobianByJet(between_a), kJetTolerance,
                       "Between a " + name);
    ExpectJacobianNear(J_between_b, GroupJacobianByJet(between_b), kJetTolerance,
                       "Between b " + name);
    ExpectJacobianNear(J_ab_a, GroupJacobianByDifferences(compose_a), kFiniteDifferenceTolerance,
                       "J_ab_a fd " + name);
    ExpectJacobianNear(J_between_a, GroupJacobianByDifferences(between_a),
                       kFiniteDifferenceTolerance, "Between a fd " + name);
  }
}

TEST(Se2, PlusAndMinusJacobiansMatchJetAndFiniteDifferences) {
  const auto poses = Poses(12);
  const auto tangents = Tangents(13);
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const SE2d& t = poses[i].pose;
    const Vector3d& tau = tangents[i].tau;
    const std::string name = poses[i].name + "/" + tangents[i].name;
    Matrix3d J_out_t, J_out_tau;
    const SE2d u = t.Plus(tau, &J_out_t, &J_out_tau);
    auto plus_t = [&](const auto& d) {
      using T = ScalarOf<decltype(d)>;
      return (t.Cast<T>() * SE2<T>::Exp(d)).Plus(tau.cast<T>());
    };
    auto plus_tau = [&](const auto& d) {
      using T = ScalarOf<decltype(d)>;
      return t.Cast<T>().Plus(tau.cast<T>() + d);
    };
    ExpectJacobianNear(J_out_t, GroupJacobianByJet(plus_t), kJetTolerance, "Plus T " + name);
    ExpectJacobianNear(J_out_tau, GroupJacobianByJet(plus_tau), kJetTolerance, "Plus tau " + name);
    ExpectJacobianNear(J_out_tau, GroupJacobianByDifferences(plus_tau), kFiniteDifferenceTolerance,
                       "Plus tau fd " + name);

    // Minus(u, t) = Log(t^-1 u) (= tau when |theta| < pi).
    Matrix3d J_d_u, J_d_t;
    u.Minus(t, &J_d_u, &J_d_t);
    auto minus_u = [&](const auto& d) {
      using T = ScalarOf<decltype(d)>;
      return (u.Cast<T>() * SE2<T>::Exp(d)).Minus(t.Cast<T>());
    };
    auto minus_t = [&](const auto& d) {
      using T = ScalarOf<decltype(d)>;
      return u.Cast<T>().Minus(t.Cast<T>() * SE2<T>::Exp(d));
    };
    ExpectJacobianNear(J_d_u, VectorJacobianByJet(minus_u), kJetTolerance, "Minus a " + name);
    ExpectJacobianNear(J_d_t, VectorJacobianByJet(minus_t), kJetTolerance, "Minus b " + name);
    ExpectJacobianNear(J_d_t, VectorJacobianByDifferences(minus_t), kFiniteDifferenceTolerance,
                       "Minus b fd " + name);
  }
}

TEST(Se2, ActJacobiansMatchJetAndFiniteDifferences) {
  const Vector2d points[] = {Vector2d::Zero(), Vector2d(1e-9, -1e-9), Vector2d(0.4, -0.7)};
  for (const PoseCase& c : Poses(14)) {
    for (const Vector2d& p : points) {
      Eigen::Matrix<double, 2, 3> J_out_t;
      Eigen::Matrix2d J_out_p;
      c.pose.Act(p, &J_out_t, &J_out_p);
      auto by_pose = [&](const auto& d) {
        using T = ScalarOf<decltype(d)>;
        return (c.pose.Cast<T>() * SE2<T>::Exp(d)).Act(p.cast<T>());
      };
      auto by_point = [&](const auto& d) {  // uses d's first two entries
        using T = ScalarOf<decltype(d)>;
        return c.pose.Cast<T>().Act(p.cast<T>() + d.template head<2>());
      };
      ExpectJacobianNear(J_out_t, VectorJacobianByJet(by_pose), kJetTolerance, "Act T " + c.name);
      ExpectJacobianNear(J_out_t, VectorJacobianByDifferences(by_pose), kFiniteDifferenceTolerance,
                         "Act T fd " + c.name);
      ExpectJacobianNear(J_out_p, VectorJacobianByJet(by_point).leftCols<2>(), kJetTolerance,
                         "Act p " + c.name);
    }
  }
}

TEST(Se2, RightJacobianInverseInvertsRightJacobian) {
  for (const TangentCase& c : Tangents(15)) {
    EXPECT_LE(
        (SE2d::RightJacobian(c.tau) * SE2d::RightJacobianInverse(c.tau) - Matrix3d::Identity())
            .cwiseAbs()
            .maxCoeff(),
        1e-14)
        << c.name;
    // Jl(tau) = Ad(Exp(tau)) Jr(tau) [Sola Eq. 45].
    EXPECT_LE((SE2d::LeftJacobian(c.tau) - SE2d::Exp(c.tau).Adjoint() * SE2d::RightJacobian(c.tau))
                  .cwiseAbs()
                  .maxCoeff(),
              1e-14)
        << c.name;
  }
}

}  // namespace
}  // namespace tactfunc
