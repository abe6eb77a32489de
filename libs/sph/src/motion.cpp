#include "rime/sph/motion.h"

#include <cmath>

namespace rime::sph {

ObjectMotion::ObjectMotion(const io::SolidObject& solid)
    : spin_axis_(solid.spin_axis), spin_rate_(solid.spin_rate), spin_center_(solid.spin_center), keyframes_(solid.keyframes) {}

void ObjectMotion::Pose(double time, Mat3<double>& rotation, Vec3d& translation) const {
  // Spin about the axis through spin_center: x' = S (x − c) + c.
  const Mat3<double> spin = AxisAngleRotation(spin_axis_, spin_rate_ * time);
  Vec3d spin_t = spin_center_ - spin * spin_center_;
  rotation = spin;
  translation = spin_t;
  if (keyframes_.empty()) return;
  // Keyframes: linear interpolation of translation and Euler angles, held before/after the ends.
  Vec3d key_translate = keyframes_.front().translate, key_rotate = keyframes_.front().rotate_deg;
  if (time >= keyframes_.back().time) {
    key_translate = keyframes_.back().translate;
    key_rotate = keyframes_.back().rotate_deg;
  } else {
    for (std::size_t k = 0; k + 1 < keyframes_.size(); ++k) {
      const io::Keyframe &a = keyframes_[k], &b = keyframes_[k + 1];
      if (time >= a.time && time < b.time) {
        const double u = (time - a.time) / (b.time - a.time);
        key_translate = a.translate + (b.translate - a.translate) * u;
        key_rotate = a.rotate_deg + (b.rotate_deg - a.rotate_deg) * u;
      }
    }
  }
  const Mat3<double> key = RotationXYZDegrees(key_rotate);
  rotation = key * spin;
  translation = key * spin_t + key_translate;
}

template <class T>
RigidMotion<T> ObjectMotion::At(double time) const {
  Mat3<double> r0, r1;
  Vec3d t0, t1;
  Pose(time, r0, t0);
  RigidMotion<T> m;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m.rotation.m[i][j] = T(r0.m[i][j]);
  m.translation = Vec3<T>(T(t0.x), T(t0.y), T(t0.z));
  if (!animated()) return m;
  const double delta = 1e-6;
  Pose(time + delta, r1, t1);
  // dR/dt Rᵀ = [ω]x ; velocity of the world origin carried by the body = dt/dt.
  Mat3<double> w = (r1 * Transpose(r0));
  const Vec3d omega{(w.m[2][1] - w.m[1][2]) / (2 * delta), (w.m[0][2] - w.m[2][0]) / (2 * delta), (w.m[1][0] - w.m[0][1]) / (2 * delta)};
  const Vec3d v_origin = (t1 - t0) / delta;
  m.angular_velocity = Vec3<T>(T(omega.x), T(omega.y), T(omega.z));
  m.linear_velocity = Vec3<T>(T(v_origin.x), T(v_origin.y), T(v_origin.z));
  m.center = m.translation;  // v(x) = dt/dt + ω × (x − t)
  return m;
}

template RigidMotion<float> ObjectMotion::At<float>(double) const;
template RigidMotion<double> ObjectMotion::At<double>(double) const;

}  // namespace rime::sph
