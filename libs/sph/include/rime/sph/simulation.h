/// @file simulation.h
/// @brief The IISPH water solver with Akinci boundaries and the non-pressure modules (spec §1–7, 11).
///
/// @code
/// rime::sph::Simulation<float> sim(scene, device);
/// sim.AddBoundaryObject(rime::io::ReadParticleFrame("ground.h5part", "boundary"));
/// sim.Initialize();                        // fluid blocks, volumes, neighbor grids
/// while (sim.time() < t_end) sim.Step(sim.NextTimeStep(t_end));
/// rime::io::WriteParticleFrame("particles.0001.h5part", sim.Snapshot(1));
/// @endcode
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "rime/core/math.h"
#include "rime/exec/device.h"
#include "rime/exec/memory.h"
#include "rime/io/particles.h"
#include "rime/io/scene.h"
#include "rime/sph/modules.h"

namespace rime::sph {

class Enclosure;

/// Wall-clock seconds spent in each part of the step (accumulated).
struct StepTimings {
  double neighbor_search = 0, non_pressure = 0, pressure_solve = 0, integration = 0, freezing = 0, other = 0;
  // Parts of neighbor_search: binning and reordering the water; the water–water and the
  // water–boundary lists, each with the kernel values and gradients stored per pair.
  double grid_build = 0, fluid_lists = 0, boundary_lists = 0;
  double total() const { return neighbor_search + non_pressure + pressure_solve + integration + freezing + other; }
};

struct StepStats {
  double dt = 0;
  int pressure_iterations = 0;
  bool converged = true;
  bool omega_fallback = false;
  // Predicted by the pressure solve (spec §6's estimate, the one η is checked against): relative,
  // (ρ − ρ0)/ρ0 of the compressed particles, summed and divided by all fluid particles.
  double average_density_error = 0;
  double max_density_error = 0;  // relative, max over fluid particles
  // Measured: the same average from the kernel-sum densities at the start of this step, i.e. what
  // the previous step's pressures actually achieved. With the default a_ii (spec §6 "splishsplash")
  // it is 2-4 times the prediction: the estimate reports about (1 − ω) of the residual, and the
  // solve counts wall particles as pushed by p_i.
  double measured_density_error = 0;
  double max_speed = 0;  // m/s after the step
  std::int64_t fluid_particles = 0;
  std::int64_t removed_particles = 0;  // left the domain during this step
  std::int64_t emitted_particles = 0;
  std::int64_t frozen_particles = 0;  // converted to ice during this step
};

template <class T>
class Simulation {
 public:
  Simulation(const io::Scene& scene, const exec::Device& device);
  ~Simulation();
  Simulation(const Simulation&) = delete;
  Simulation& operator=(const Simulation&) = delete;

  /// Adds one object's boundary particles (a rime-boundary file). Call before Initialize.
  void AddBoundaryObject(const io::ParticleFrame& boundary, const std::string& object_name);
  /// Creates the scene's fluid blocks, computes boundary volumes and builds the static grids.
  void Initialize();
  /// Restores the complete state from a frame written by Snapshot (after AddBoundaryObject calls).
  void Restore(const io::ParticleFrame& frame);

  /// Time step for the next step (spec §7), shortened so that a step ends exactly at `next_stop`.
  double NextTimeStep(double next_stop) const;
  /// Advances by dt; throws rime::Error(kDiverged) naming the step and worst particle on NaN or a
  /// density error above the scene's limit.
  StepStats Step(double dt);

  /// The complete state as a frame (a restartable checkpoint).
  io::ParticleFrame Snapshot(std::int64_t frame_number) const;

  double time() const { return time_; }
  std::int64_t step_count() const { return step_count_; }
  std::int64_t fluid_count() const;
  std::int64_t boundary_count() const;
  std::int64_t removed_total() const { return removed_total_; }
  std::int64_t ice_count() const;
  const ModuleRegistry& modules() const { return modules_; }
  const StepTimings& timings() const { return timings_; }
  void EnableTimings(bool on) { timing_enabled_ = on; }
  /// Bytes of particle and neighbor arrays currently allocated, of every module or of one
  /// ("core", "freezing", "surface_tension").
  std::size_t MemoryBytes(const std::string& module = {}) const;

  // Host copies for tests and tools (slow: copies from the device).
  std::vector<Vec3<T>> Positions() const;
  std::vector<Vec3<T>> Velocities() const;
  std::vector<T> Densities() const;  // from the last step
  std::vector<T> Pressures() const;  // from the last step
  std::vector<std::int64_t> Ids() const;
  std::vector<Vec3<T>> BoundaryPositions() const;
  std::vector<T> BoundaryVolumes() const;
  /// Non-pressure accelerations of the last step (for momentum checks).
  std::vector<Vec3<T>> NonPressureAccelerations() const;

  /// Overwrites fluid positions/velocities (tests). Sizes must match fluid_count().
  void SetFluidState(const std::vector<Vec3<T>>& x, const std::vector<Vec3<T>>& v);

  /// The particle groups (src/state.h), for tests that check them against frames.
  struct State;
  const State& state() const { return *state_; }

 private:
  void NeighborSearch();
  double ComputeDensity();  // returns the measured average compression (StepStats::measured_density_error)
  void NonPressureAccelerations(double dt);
  StepStats SolvePressure(double dt, double omega);
  void Integrate(double dt);
  void SeedWater(const Enclosure& enclosure);
  // Replaces the water with these particles (new ids, every other attribute at its fill value).
  void SetWater(const std::vector<Vec3<T>>& x, const std::vector<Vec3<T>>& v);
  void RemoveOutsideDomain(StepStats& stats);
  void Emit(double dt, StepStats& stats);
  void UpdateBoundaryMotion(double t);
  void RecomputeBoundaryVolumes();
  void FinishBoundaryVolumes();  // ice volume cap, then Ψ = ρ0 V
  void ComputeDomain(const std::vector<Vec3<T>>& fluid);
  void CheckDivergence(const StepStats& stats) const;
  void Freeze(double dt);
  void ConvertToIce(const exec::DeviceArray<std::uint32_t>& frozen_list, Index frozen, double when);

  io::Scene scene_;
  exec::Device device_;
  std::unique_ptr<State> state_;
  ModuleRegistry modules_;
  StepTimings timings_;
  bool timing_enabled_ = false;
  double time_ = 0;
  std::int64_t step_count_ = 0;
  std::int64_t next_id_ = 0;
  std::int64_t removed_total_ = 0;
  double diffusion_pending_ = 0;        // film diffusion time not yet applied, s
  std::vector<double> emitter_travel_;  // distance travelled since each emitter's last layer, m
  std::vector<std::string> object_names_;
  Vec3<T> domain_min_{}, domain_max_{};  // particles leaving this box are removed
  Vec3<T> lattice_origin_{};             // shared origin of the water and boundary grids
  bool initialized_ = false;
};

extern template class Simulation<float>;
extern template class Simulation<double>;

}  // namespace rime::sph
