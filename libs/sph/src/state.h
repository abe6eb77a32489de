/// @file state.h
/// @brief The solver's particle state as attribute groups (rime/exec/attributes.h), each declaring
/// its arrays once: water (persistent and per step), boundary, and the modules' own groups (the
/// freezing groups are libs/freeze's), which exist only while their module is on. Private to libs/sph.
#pragma once

#include <chrono>
#include <optional>
#include <vector>

#include "frame_rows.h"
#include "rime/exec/attributes.h"
#include "rime/freeze/freezing.h"
#include "rime/io/scene.h"
#include "rime/neighbors/grid.h"
#include "rime/sph/modules.h"
#include "rime/sph/motion.h"
#include "rime/sph/simulation.h"

namespace rime::sph {

using exec::DeviceArray;
using exec::Names;
using exec::ScratchPool;
using freeze::FreezingBoundary;
using freeze::FreezingFluid;
using freeze::FreezingWork;

// Water and boundary rows of a frame share these datasets (x y z, vx vy vz, id).
inline constexpr AttributeInfo kPositions{.name = "", .checkpointed = true, .names = Names::kXyz};
inline constexpr AttributeInfo kVelocities{.name = "v", .checkpointed = true, .names = Names::kXyz};
inline constexpr AttributeInfo kIds{.name = "id", .checkpointed = true};

/// Water state carried from step to step and in frames; reordered with the particles.
template <class T>
struct FluidState : exec::AttributeGroup<FluidState<T>> {
  static constexpr const char* kModule = "core";
  explicit FluidState(const exec::Device& d) : x(d), v(d), id(d), pressure(d), density(d) {}
  DeviceArray<Vec3<T>> x, v;
  DeviceArray<std::int64_t> id;
  DeviceArray<T> pressure;  // of the last step: the next solve's warm start
  DeviceArray<T> density;   // of the last step; the rest density until the first step

  template <class Self, class F>
  static void Visit(Self& s, F& f) {
    f(kPositions, s.x);
    f(kVelocities, s.v);
    f(kIds, s.id);
    f(AttributeInfo{.name = "pressure", .checkpointed = true}, s.pressure);
    f(AttributeInfo{.name = "density", .checkpointed = true, .fill = Fill::kRestDensity}, s.density);
  }
};

/// Water quantities computed within one step (sized, not reordered, by the step).
template <class T>
struct FluidStep : exec::AttributeGroup<FluidStep<T>> {
  static constexpr const char* kModule = "core";
  explicit FluidStep(const exec::Device& d)
      : v_adv(d),
        accel(d),
        d_ii(d),
        s(d),
        density_error(d),
        pressure(d),
        pressure_next(d),
        advected_error(d),
        a_ii(d),
        compression(d),
        scratch(d) {}
  DeviceArray<Vec3<T>> v_adv, accel, d_ii, s;
  DeviceArray<T> density_error, pressure, pressure_next, advected_error, a_ii, compression, scratch;

  template <class Self, class F>
  static void Visit(Self& s, F& f) {
    f(AttributeInfo{.name = "advected_velocity"}, s.v_adv);
    f(AttributeInfo{.name = "acceleration"}, s.accel);
    f(AttributeInfo{.name = "d_ii"}, s.d_ii);
    f(AttributeInfo{.name = "displacement_sum"}, s.s);
    f(AttributeInfo{.name = "density_error"}, s.density_error);
    f(AttributeInfo{.name = "pressure_iterate"}, s.pressure);
    f(AttributeInfo{.name = "pressure_next"}, s.pressure_next);
    f(AttributeInfo{.name = "advected_density_error"}, s.advected_error);
    f(AttributeInfo{.name = "a_ii"}, s.a_ii);
    f(AttributeInfo{.name = "compression"}, s.compression);
    f(AttributeInfo{.name = "scratch"}, s.scratch);
  }
};

/// He 2014 surface tension: colour field and its energy, per step.
template <class T>
struct SurfaceColorField : exec::AttributeGroup<SurfaceColorField<T>> {
  static constexpr const char* kModule = "surface_tension";
  explicit SurfaceColorField(const exec::Device& d) : color(d), energy(d) {}
  DeviceArray<T> color, energy;

  template <class Self, class F>
  static void Visit(Self& s, F& f) {
    f(AttributeInfo{.name = "color"}, s.color);
    f(AttributeInfo{.name = "color_energy"}, s.energy);
  }
};

/// Akinci 2013 surface tension: surface normals, per step.
template <class T>
struct SurfaceNormals : exec::AttributeGroup<SurfaceNormals<T>> {
  static constexpr const char* kModule = "surface_tension";
  explicit SurfaceNormals(const exec::Device& d) : normal(d) {}
  DeviceArray<Vec3<T>> normal;

  template <class Self, class F>
  static void Visit(Self& s, F& f) {
    f(AttributeInfo{.name = "surface_normal"}, s.normal);
  }
};

/// Boundary particles: the solids of the boundary files, then ice in the order it froze. Written
/// to frames (and read back) only with freezing on: otherwise the boundary files are the state.
template <class T>
struct BoundaryState : exec::AttributeGroup<BoundaryState<T>> {
  static constexpr const char* kModule = "core";
  explicit BoundaryState(const exec::Device& d) : x(d), v(d), local(d), object(d), phase(d), id(d), volume(d), psi(d) {}
  DeviceArray<Vec3<T>> x, v;
  DeviceArray<Vec3<T>> local;  // rest-pose position on its object
  DeviceArray<std::uint32_t> object;
  DeviceArray<std::uint8_t> phase;
  DeviceArray<std::int64_t> id;
  DeviceArray<T> volume;  // Akinci V_b, as the run has it (updated near new ice only)
  DeviceArray<T> psi;     // Ψ_b = ρ0 V_b

  template <class Self, class F>
  static void Visit(Self& s, F& f) {
    f(kPositions, s.x);
    f(kVelocities, s.v);
    f(AttributeInfo{.name = "local", .checkpointed = true}, s.local);
    f(AttributeInfo{.name = "object_id", .checkpointed = true}, s.object);
    f(AttributeInfo{.name = "phase", .checkpointed = true}, s.phase);
    f(kIds, s.id);
    f(AttributeInfo{.name = "volume", .checkpointed = true}, s.volume);
    f(AttributeInfo{.name = "psi"}, s.psi);
  }
};

/// Pairs of the water's neighborhoods and their kernel values, rebuilt every step.
template <class T>
struct Neighborhoods : exec::AttributeGroup<Neighborhoods<T>> {
  static constexpr const char* kModule = "core";
  explicit Neighborhoods(const exec::Device& d) : ff(d), fb(d), ff_w(d), fb_w(d), ff_grad(d), fb_grad(d) {}
  neighbors::NeighborList ff, fb;
  DeviceArray<T> ff_w, fb_w;
  DeviceArray<Vec3<T>> ff_grad, fb_grad;

  template <class Self, class F>
  static void Visit(Self& s, F& f) {
    f(AttributeInfo{.name = "ff_offsets"}, s.ff.offsets);
    f(AttributeInfo{.name = "ff_indices"}, s.ff.indices);
    f(AttributeInfo{.name = "fb_offsets"}, s.fb.offsets);
    f(AttributeInfo{.name = "fb_indices"}, s.fb.indices);
    f(AttributeInfo{.name = "ff_w"}, s.ff_w);
    f(AttributeInfo{.name = "fb_w"}, s.fb_w);
    f(AttributeInfo{.name = "ff_grad"}, s.ff_grad);
    f(AttributeInfo{.name = "fb_grad"}, s.fb_grad);
  }
};

/// Creates `group` when its module is on and `wanted` holds, recording its attributes.
template <class Group>
void AllocateIf(std::optional<Group>& group, const exec::Device& device, ModuleRegistry& modules, bool wanted = true) {
  if (!wanted || !modules.Enabled(Group::kModule)) return;
  group.emplace(device);
  group->ForEach([&](const AttributeInfo& a, const auto&) { modules.RecordAttribute(Group::kModule, a.name); });
}

template <class T>
struct Simulation<T>::State {
  State(const exec::Device& d, const io::Scene& scene, ModuleRegistry& modules)
      : fluid(d), step(d), boundary(d), pairs(d), pool(d), fluid_grid(d), boundary_grid(d), motions(d), keep(d), slot(d), order(d) {
    AllocateIf(color_field, d, modules, scene.surface_tension.model != io::SurfaceTensionModel::kAkinci2013);
    AllocateIf(normals, d, modules, scene.surface_tension.model == io::SurfaceTensionModel::kAkinci2013);
    AllocateIf(freezing, d, modules);
    AllocateIf(freezing_fluid, d, modules, scene.freezing.freeze_delay > 0);
    AllocateIf(freezing_work, d, modules);
  }

  FluidState<T> fluid;
  FluidStep<T> step;
  std::optional<SurfaceColorField<T>> color_field;
  std::optional<SurfaceNormals<T>> normals;
  BoundaryState<T> boundary;
  std::optional<FreezingBoundary<T>> freezing;
  std::optional<FreezingFluid<T>> freezing_fluid;
  std::optional<FreezingWork<T>> freezing_work;
  Neighborhoods<T> pairs;
  ScratchPool pool;  // reorder buffers

  neighbors::UniformGrid<T> fluid_grid, boundary_grid;
  // Objects.
  std::vector<ObjectMotion> object_motions;  // index = object id
  std::vector<Vec3d> initial_normals;        // host, from the boundary files (zero when absent); used once by Initialize
  DeviceArray<RigidMotion<T>> motions;
  bool any_animated = false;
  // Compaction.
  DeviceArray<std::uint32_t> keep, slot, order;
  std::int64_t ice_count = 0;

  /// Calls f(group) for every water group that exists (they share the particle order).
  template <class F>
  void ForEachFluidGroup(F&& f) {
    FluidGroups(*this, f);
  }
  template <class F>
  void ForEachFluidGroup(F&& f) const {
    FluidGroups(*this, f);
  }
  /// Calls f(group) for every boundary group that exists.
  template <class F>
  void ForEachBoundaryGroup(F&& f) {
    BoundaryGroups(*this, f);
  }
  template <class F>
  void ForEachBoundaryGroup(F&& f) const {
    BoundaryGroups(*this, f);
  }
  template <class Self, class F>
  static void FluidGroups(Self& s, F& f) {
    f(s.fluid);
    if (s.freezing_fluid) f(*s.freezing_fluid);
  }
  template <class Self, class F>
  static void BoundaryGroups(Self& s, F& f) {
    f(s.boundary);
    if (s.freezing) f(*s.freezing);
  }

  /// Calls f(module, group) for every group that exists.
  template <class F>
  void ForEachGroup(F&& f) const {
    f(FluidState<T>::kModule, fluid);
    f(FluidStep<T>::kModule, step);
    f(BoundaryState<T>::kModule, boundary);
    f(Neighborhoods<T>::kModule, pairs);
    if (color_field) f(SurfaceColorField<T>::kModule, *color_field);
    if (normals) f(SurfaceNormals<T>::kModule, *normals);
    if (freezing) f(FreezingBoundary<T>::kModule, *freezing);
    if (freezing_fluid) f(FreezingFluid<T>::kModule, *freezing_fluid);
    if (freezing_work) f(FreezingWork<T>::kModule, *freezing_work);
  }

  /// Keeps the water particles order[0..count) in that order.
  void GatherFluid(const exec::Device& device, Index count) {
    ForEachFluidGroup([&](auto& group) { exec::GatherGroup(device, group, order.data(), count, pool); });
  }

  Index n() const { return static_cast<Index>(fluid.x.size()); }
  Index nb() const { return static_cast<Index>(boundary.x.size()); }
  Pairs<T> FF() const { return {pairs.ff.offsets.data(), pairs.ff.indices.data(), pairs.ff_w.data(), pairs.ff_grad.data()}; }
  Pairs<T> FB() const { return {pairs.fb.offsets.data(), pairs.fb.indices.data(), pairs.fb_w.data(), pairs.fb_grad.data()}; }
};

}  // namespace rime::sph

namespace rime::sph {

template <class T>
Vec3<T> ToT(const Vec3d& v) {
  return {T(v.x), T(v.y), T(v.z)};
}

/// Adds the wall-clock time of its scope (after the device finished) to `slot` when enabled.
class PhaseTimer {
 public:
  PhaseTimer(const exec::Device& device, bool enabled, double& slot) : device_(device), enabled_(enabled), slot_(slot) {
    if (enabled_) start_ = std::chrono::steady_clock::now();
  }
  ~PhaseTimer() {
    if (!enabled_) return;
    exec::Synchronize(device_);
    slot_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  const exec::Device& device_;
  bool enabled_;
  double& slot_;
  std::chrono::steady_clock::time_point start_;
};

/// Where a scene value came from, for error messages: "file: field", or the field alone for scenes
/// built in code.
inline std::string SceneField(const io::Scene& scene, const std::string& field) {
  return scene.file.empty() ? field : scene.file.string() + ": " + field;
}

}  // namespace rime::sph
