/// @file motion.h
/// @brief Kinematic (animated) solids: keyframed transforms plus a constant spin (paper's rotating
/// Buddha scene). Boundary particles and ice attached to the object follow it rigidly.
#pragma once

#include <vector>

#include "rime/io/scene.h"
#include "rime/sph/kernels.h"

namespace rime::sph {

class ObjectMotion {
 public:
  ObjectMotion() = default;  // static
  explicit ObjectMotion(const io::SolidObject& solid);

  bool animated() const { return spin_rate_ != 0 || !keyframes_.empty(); }
  /// Pose relative to the rest pose (the boundary file's positions): x(t) = R x_rest + t.
  void Pose(double time, Mat3<double>& rotation, Vec3d& translation) const;
  /// Pose and velocities (finite difference over 1 µs, exact for constant spin).
  template <class T>
  RigidMotion<T> At(double time) const;

 private:
  Vec3d spin_axis_{0, 0, 1};
  double spin_rate_ = 0;
  Vec3d spin_center_{0, 0, 0};
  std::vector<io::Keyframe> keyframes_;
};

}  // namespace rime::sph
