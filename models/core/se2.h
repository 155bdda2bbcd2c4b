// Copyright 2026 The tactfunc Authors.
//
// SE2<T>: a planar rigid transform (the in-hand pose of a tool on a tactile sensor),
// a small header-only value type after Sophus (Strasdat et al.) with manif-style
// Jacobians (Sola, Deray & Atchuthan, "A micro Lie theory for state estimation in
// robotics", 2018; we cite its equations as [Sola Eq. n]).
//
// Why our own. No Debian 12 package serves: Sophus and manif are not packaged, and
// Eigen's Rotation2D/Transform have no Exp/Log or Jacobians. SE(2) is small enough to
// write, test against ceres::Jet autodiff and own. The names follow Sophus (Exp, Log,
// Adjoint, foo_T_bar) and the Jacobian out-parameters follow manif (J_out_in).
//
// Frames. A pose is named after the frames it maps between: sensor_T_object maps
// points from the object (tool) frame into the sensor frame,
//   p_sensor = sensor_T_object * p_object = R(yaw) p_object + t,
// and sensor_T_object * object_T_marker = sensor_T_marker.
//
// Representation. The rotation is stored as ONE angle, kept in (-pi, pi] (every
// constructor and operation normalises it), plus the translation t = (x, y) in the
// units of the caller (metres throughout tactfunc). x(), y(), yaw() read it.
//
// Tangent space (the Lie algebra se(2)), ordered (x, y, theta) = (rho_x, rho_y, theta):
//   Exp(rho, theta) = ( R(theta), V(theta) rho ),
//   V(theta) = [ A  -B ]     A = sin(theta) / theta,  B = (1 - cos(theta)) / theta
//              [ B   A ],
// so rho is NOT the translation unless theta = 0 [Sola Eq. 156]. Log inverts Exp for
// rotations in (-pi, pi]: Log(Exp(v)) = v for |theta| < pi, Exp(Log(T)) = T always.
// Near theta = 0 (|theta| < 1e-2; 0.1 for float) all the sin/theta-type terms switch to Taylor
// series accurate to machine precision, so values AND Jet derivatives stay exact at theta ~ 0 (even
// theta = 1e-12 or exactly 0).
//
// Perturbations and covariances: RIGHT (local, body-frame) perturbations throughout.
// A small uncertainty delta in R^3 perturbs a pose as  T * Exp(delta), and every
// covariance in tactfunc is the covariance of that delta: a 3x3 matrix in the tangent
// space at the mean, ordered (x, y, theta) [Sola Sec. 7]. Every Jacobian J_out_in is
// the right Jacobian d Log(out^-1 * out(in * Exp(d))) / d d at d = 0 [Sola Eq. 41],
// so covariances propagate as  Sigma_out = J_out_in Sigma_in J_out_in^T. (For vector
// inputs/outputs -- tangents, points -- the ordinary derivative is used on that side.)
//
// Scalar type T: double, float or ceres::Jet (every function is written with
// argument-dependent sin/cos/atan2 so Ceres' AutoDiff can differentiate through it).
#ifndef TACTFUNC_MODELS_CORE_SE2_H_
#define TACTFUNC_MODELS_CORE_SE2_H_

#include <cmath>
#include <limits>
#include <ostream>
#include <type_traits>

#include "Eigen/Core"

namespace tactfunc {

template <typename T>
class SE2 {
 public:
  using Scalar = T;
  static constexpr int DoF = 3;            // tangent dimension
  using Tangent = Eigen::Matrix<T, 3, 1>;  // (x, y, theta)
  using Point = Eigen::Matrix<T, 2, 1>;
  using Jacobian = Eigen::Matrix<T, 3, 3>;       // tangent x tangent
  using PointJacobian = Eigen::Matrix<T, 2, 3>;  // point x tangent
  using RotationMatrix = Eigen::Matrix<T, 2, 2>;

  // Below this |theta| the sin/theta-type coefficients use Taylor series (truncation
  // error < 1e-20 there for double; the closed forms lose < 1e-11 relative accuracy
  // above it). float switches later (0.1: truncation < 1e-13, below float's epsilon)
  // because its closed forms lose ~eps/theta^2 to cancellation.
  static constexpr double kSmallAngle = std::is_same<T, float>::value ? 0.1 : 1e-2;
  static constexpr double kPi = 3.14159265358979323846;

  // The identity.
  SE2() : angle_(T(0)), translation_(T(0), T(0)) {}
  // Rotation by `angle` (rad, any value; normalised into (-pi, pi]) then translation.
  SE2(const T& angle, const Point& translation)
      : angle_(NormalizeAngle(angle)), translation_(translation) {}

  static SE2 Identity() { return SE2(); }
  // x, y in the caller's length unit, yaw in rad (any value; normalised).
  static SE2 FromXYYaw(const T& x, const T& y, const T& yaw) { return SE2(yaw, Point(x, y)); }
  static SE2 Rot(const T& yaw) { return SE2(yaw, Point(T(0), T(0))); }
  static SE2 Trans(const T& x, const T& y) { return SE2(T(0), Point(x, y)); }

  const T& x() const { return translation_.x(); }
  const T& y() const { return translation_.y(); }
  // The rotation angle in (-pi, pi].
  const T& yaw() const { return angle_; }
  const Point& translation() const { return translation_; }
  RotationMatrix Rotation() const {
    using std::cos;
    using std::sin;
    const T c = cos(angle_), s = sin(angle_);
    RotationMatrix r;
    r << c, -s, s, c;
    return r;
  }
  // 3x3 homogeneous matrix [R t; 0 0 1].
  Eigen::Matrix<T, 3, 3> Matrix() const {
    Eigen::Matrix<T, 3, 3> m = Eigen::Matrix<T, 3, 3>::Identity();
    m.template topLeftCorner<2, 2>() = Rotation();
    m.template topRightCorner<2, 1>() = translation_;
    return m;
  }

  // ---- Lie group operations ---------------------------------------------------------
  // Exp: tangent (x, y, theta) -> group. J_T_tau (optional) = Jr(tau) [Sola Eq. 163].
  static SE2 Exp(const Tangent& tau, Jacobian* J_T_tau = nullptr) {
    const Coefficients k(tau[2]);
    Point t(k.A * tau[0] - k.B * tau[1], k.B * tau[0] + k.A * tau[1]);
    if (J_T_tau != nullptr) *J_T_tau = RightJacobian(tau);
    return SE2(tau[2], t);
  }

  // Log: group -> tangent (x, y, theta) with theta in (-pi, pi].
  // J_tau_T (optional) = Jr^-1(Log(T)).
  Tangent Log(Jacobian* J_tau_T = nullptr) const {
    const T& theta = angle_;
    const T a = HalfThetaCotHalfTheta(theta);
    const T h = theta / T(2);
    Tangent tau(a * translation_.x() + h * translation_.y(),
                -h * translation_.x() + a * translation_.y(), theta);
    if (J_tau_T != nullptr) *J_tau_T = RightJacobianInverse(tau);
    return tau;
  }

  // T^-1. J_inv_T (optional) = -Adjoint() [Sola Eq. 62].
  SE2 Inverse(Jacobian* J_inv_T = nullptr) const {
    if (J_inv_T != nullptr) *J_inv_T = -Adjoint();
    return SE2(-angle_, -(Rotation().transpose() * translation_));
  }

  // a * b, e.g. sensor_T_object = sensor_T_gripper * gripper_T_object.
  // J_ab_a = Ad(b^-1), J_ab_b = I [Sola Eqs. 63, 64].
  static SE2 Compose(const SE2& a, const SE2& b, Jacobian* J_ab_a = nullptr,
                     Jacobian* J_ab_b = nullptr) {
    if (J_ab_a != nullptr) *J_ab_a = b.Inverse().Adjoint();
    if (J_ab_b != nullptr) J_ab_b->setIdentity();
    return SE2(a.angle_ + b.angle_, a.translation_ + a.Rotation() * b.translation_);
  }
  SE2 operator*(const SE2& b) const { return Compose(*this, b); }
  SE2& operator*=(const SE2& b) { return *this = Compose(*this, b); }

  // a^-1 * b: the pose of b relative to a (a_T_b from world_T_a and world_T_b).
  // J_ab_a = -Ad((a^-1 b)^-1), J_ab_b = I.
  static SE2 Between(const SE2& a, const SE2& b, Jacobian* J_ab_a = nullptr,
                     Jacobian* J_ab_b = nullptr) {
    const SE2 ab = Compose(a.Inverse(), b);
    if (J_ab_a != nullptr) *J_ab_a = -ab.Inverse().Adjoint();
    if (J_ab_b != nullptr) J_ab_b->setIdentity();
    return ab;
  }

  // The image of a point: R p + t. J_out_T = [R, R (-p_y, p_x)^T] (right perturbation
  // of this pose), J_out_p = R.
  Point Act(const Point& p, PointJacobian* J_out_T = nullptr,
            Eigen::Matrix<T, 2, 2>* J_out_p = nullptr) const {
    const RotationMatrix r = Rotation();
    if (J_out_T != nullptr) {
      J_out_T->template leftCols<2>() = r;
      J_out_T->col(2) = r * Point(-p.y(), p.x());
    }
    if (J_out_p != nullptr) *J_out_p = r;
    return r * p + translation_;
  }
  Point operator*(const Point& p) const { return Act(p); }

  // Adjoint matrix: T * Exp(tau) = Exp(Adjoint() * tau) * T.
  //   Ad = [ R   (y, -x)^T ]
  //        [ 0      1      ]        [Sola Eq. 159]
  Jacobian Adjoint() const {
    Jacobian ad = Jacobian::Zero();
    ad.template topLeftCorner<2, 2>() = Rotation();
    ad(0, 2) = translation_.y();
    ad(1, 2) = -translation_.x();
    ad(2, 2) = T(1);
    return ad;
  }

  // Right plus: this * Exp(tau). J_out_T = Ad(Exp(tau)^-1), J_out_tau = Jr(tau).
  SE2 Plus(const Tangent& tau, Jacobian* J_out_T = nullptr, Jacobian* J_out_tau = nullptr) const {
    const SE2 e = Exp(tau, J_out_tau);
    if (J_out_T != nullptr) *J_out_T = e.Inverse().Adjoint();
    return Compose(*this, e);
  }
  // Right minus: Log(b^-1 * this), the tangent delta with this = b * Exp(delta).
  // J_out_this = Jr^-1(delta), J_out_b = -Jl^-1(delta) = -Jr^-1(-delta).
  Tangent Minus(const SE2& b, Jacobian* J_out_this = nullptr, Jacobian* J_out_b = nullptr) const {
    const Tangent delta = Compose(b.Inverse(), *this).Log();
    if (J_out_this != nullptr) *J_out_this = RightJacobianInverse(delta);
    if (J_out_b != nullptr) *J_out_b = -RightJacobianInverse(-delta);
    return delta;
  }

  // Right Jacobian of Exp: Exp(tau + d) ~= Exp(tau) * Exp(Jr(tau) d) [Sola Eq. 163]:
  //   Jr = [  A   B   x D - y C ]   C = (1 - cos(theta)) / theta^2
  //        [ -B   A   x C + y D ]   D = (theta - sin(theta)) / theta^2
  //        [  0   0       1     ]
  static Jacobian RightJacobian(const Tangent& tau) {
    const Coefficients k(tau[2]);
    Jacobian j = Jacobian::Identity();
    j(0, 0) = k.A;
    j(0, 1) = k.B;
    j(1, 0) = -k.B;
    j(1, 1) = k.A;
    j(0, 2) = tau[0] * k.D - tau[1] * k.C;
    j(1, 2) = tau[0] * k.C + tau[1] * k.D;
    return j;
  }
  // Jr(tau)^-1, in closed form: the 2x2 block inverts to [a -theta/2; theta/2 a] with
  // a = (theta/2) cot(theta/2); regular for |theta| < 2 pi.
  static Jacobian RightJacobianInverse(const Tangent& tau) {
    const T a = HalfThetaCotHalfTheta(tau[2]);
    const T h = tau[2] / T(2);
    const Jacobian jr = RightJacobian(tau);
    Jacobian inv = Jacobian::Identity();
    inv(0, 0) = a;
    inv(0, 1) = -h;
    inv(1, 0) = h;
    inv(1, 1) = a;
    inv.template topRightCorner<2, 1>() =
        -(inv.template topLeftCorner<2, 2>() * jr.template topRightCorner<2, 1>());
    return inv;
  }
  // Left Jacobians: Jl(tau) = Jr(-tau).
  static Jacobian LeftJacobian(const Tangent& tau) { return RightJacobian(-tau); }
  static Jacobian LeftJacobianInverse(const Tangent& tau) { return RightJacobianInverse(-tau); }

  // ---- Utilities ----------------------------------------------------------------------
  // An angle in (-pi, pi]. Values already inside are returned unchanged (bit-exact);
  // others go through atan2(sin, cos), which is exact in derivative (d/da = 1) for Jets
  // and keeps NaN as NaN.
  static T NormalizeAngle(const T& angle) {
    using std::atan2;
    using std::cos;
    using std::sin;
    const T pi(kPi);
    if (angle > -pi && angle <= pi) return angle;
    T wrapped = atan2(sin(angle), cos(angle));
    if (wrapped <= -pi) wrapped += T(2 * kPi);
    return wrapped;
  }

  // The same pose in scalar type U (double -> float, double -> Jet, float -> double).
  template <typename U>
  SE2<U> Cast() const {
    return SE2<U>(static_cast<U>(angle_), translation_.template cast<U>());
  }

  // Component-wise comparison: |dx|, |dy| <= tolerance and the wrapped angle
  // difference <= tolerance (so yaw pi and -pi + 1e-15 compare equal). Floating T only.
  bool IsApprox(const SE2& other, const T& tolerance) const {
    using std::abs;
    return abs(x() - other.x()) <= tolerance && abs(y() - other.y()) <= tolerance &&
           abs(NormalizeAngle(angle_ - other.angle_)) <= tolerance;
  }

 private:
  // The trigonometric coefficients of V(theta) and Jr(theta), Taylor near 0.
  struct Coefficients {
    T A, B, C, D;  // sin/t, (1-cos)/t, (1-cos)/t^2, (t-sin)/t^2
    explicit Coefficients(const T& t) {
      using std::cos;
      using std::sin;
      const T t2 = t * t;
      if (t2 < T(kSmallAngle * kSmallAngle)) {
        // Next terms: t^8/9!, t^9/10!, t^8/10!, t^9/11! -- below 1e-21 for |t| < 1e-2.
        A = T(1) - t2 / T(6) * (T(1) - t2 / T(20) * (T(1) - t2 / T(42)));
        C = T(0.5) - t2 / T(24) * (T(1) - t2 / T(30) * (T(1) - t2 / T(56)));
        B = t * C;
        D = t / T(6) * (T(1) - t2 / T(20) * (T(1) - t2 / T(42) * (T(1) - t2 / T(72))));
      } else {
        const T s = sin(t), half_s = sin(t / T(2));
        A = s / t;
        C = T(2) * half_s * half_s / t2;  // 1 - cos t = 2 sin^2(t/2), no cancellation
        B = t * C;
        D = (t - s) / t2;
      }
    }
  };
  // (theta/2) cot(theta/2) = (theta/2) cos(theta/2) / sin(theta/2); 1 at theta = 0.
  static T HalfThetaCotHalfTheta(const T& theta) {
    using std::cos;
    using std::sin;
    const T t2 = theta * theta;
    if (t2 < T(kSmallAngle * kSmallAngle)) {
      // 1 - t^2/12 - t^4/720 - t^6/30240 - ...
      return T(1) - t2 / T(12) * (T(1) + t2 / T(60) * (T(1) + t2 / T(42)));
    }
    const T h = theta / T(2);
    return h * cos(h) / sin(h);
  }

  T angle_;
  Point translation_;
};

using SE2d = SE2<double>;
using SE2f = SE2<float>;

// Prints "SE2(x, y, yaw)" (floating T).
template <typename T>
std::ostream& operator<<(std::ostream& os, const SE2<T>& pose) {
  return os << "SE2(x=" << pose.x() << ", y=" << pose.y() << ", yaw=" << pose.yaw() << ")";
}

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_CORE_SE2_H_
