#include "rime/sph/simulation.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <type_traits>

#include "rime/boundary/volume_kernels.h"
#include "rime/boundary/volumes.h"
#include "rime/core/error.h"
#include "rime/core/kernel.h"
#include "rime/core/log.h"
#include "rime/exec/memory.h"
#include "rime/exec/parallel.h"
#include "rime/freeze/kernels.h"
#include "rime/neighbors/grid.h"
#include "rime/sph/enclosure.h"
#include "rime/sph/kernels.h"
#include "rime/sph/motion.h"

RIME_SPH_KERNELS(RIME_INSTANTIATE_CPU_KERNEL)

namespace rime::sph {

using exec::DeviceArray;

template <class T>
struct Simulation<T>::State {
  explicit State(const exec::Device& d)
      : x(d), v(d), v_adv(d), accel(d), d_ii(d), s(d), density(d), density_error(d), pressure(d), pressure_next(d),
        pressure_previous(d), advected_error(d), a_ii(d), compression(d), scratch(d), id(d), color(d), energy(d), surface_normal(d),
        tmp_vec(d), tmp_scalar(d), tmp_id(d), bx(d), bv(d), blocal(d), bpsi(d), bvol(d), bobject(d), bphase(d), bid(d),
        fluid_grid(d), boundary_grid(d), ff(d), fb(d), ff_w(d), fb_w(d), ff_grad(d), fb_grad(d), motions(d), keep(d),
        slot(d), order(d), film(d), growth(d), growth_valid(d), ice_kind(d), ice_time(d), ice_d(d), fluid_d(d), fluid_flag(d),
        boundary_active(d), active_list(d), decision(d), trigger(d), frozen(d), wet(d), region(d), region_list(d), energy_solid(d),
        energy_ice(d), laplacian(d), lambda(d), active_x(d), bf(d), contact_time(d) {}

  // Fluid state (persistent across steps, reordered with the particles).
  DeviceArray<Vec3<T>> x, v;
  // Per-step fluid quantities.
  DeviceArray<Vec3<T>> v_adv, accel, d_ii, s;
  DeviceArray<T> density, density_error, pressure, pressure_next, pressure_previous, advected_error, a_ii, compression, scratch;
  DeviceArray<std::int64_t> id;
  // Surface tension module: He 2014 colour field and energy, or Akinci 2013 normals.
  DeviceArray<T> color, energy;
  DeviceArray<Vec3<T>> surface_normal;
  // Reordering buffers.
  DeviceArray<Vec3<T>> tmp_vec;
  DeviceArray<T> tmp_scalar;
  DeviceArray<std::int64_t> tmp_id;
  // Boundary particles (solids, later ice).
  DeviceArray<Vec3<T>> bx, bv, blocal;
  DeviceArray<T> bpsi, bvol;  // Ψ_b = ρ0 V_b and V_b
  DeviceArray<std::uint32_t> bobject;
  DeviceArray<std::uint8_t> bphase;
  DeviceArray<std::int64_t> bid;
  // Neighborhoods.
  neighbors::UniformGrid<T> fluid_grid, boundary_grid;
  neighbors::NeighborList ff, fb;
  DeviceArray<T> ff_w, fb_w;
  DeviceArray<Vec3<T>> ff_grad, fb_grad;
  // Objects.
  std::vector<ObjectMotion> object_motions;  // index = object id
  std::vector<Vec3d> initial_normals;        // host, from the boundary files (zero when absent); used once by Initialize
  DeviceArray<RigidMotion<T>> motions;
  bool any_animated = false;
  // Compaction.
  DeviceArray<std::uint32_t> keep, slot, order;
  // Freezing module (allocated only when it is on).
  DeviceArray<T> film;                      // boundary: Γ/Γ_max
  DeviceArray<Vec3<T>> growth;              // boundary: gv
  DeviceArray<std::uint8_t> growth_valid;   // boundary
  DeviceArray<std::uint8_t> ice_kind;       // boundary: 0 solid, 1 glaze, 2 icicle
  DeviceArray<double> ice_time;             // boundary: creation time, s
  DeviceArray<freeze::Sym6<T>> ice_d;       // boundary: anisotropy D frozen with the particle
  DeviceArray<freeze::Sym6<T>> fluid_d;     // fluid: anisotropy D of this step
  DeviceArray<std::uint32_t> fluid_flag, boundary_active, active_list, decision, trigger, frozen, wet, region, region_list;
  DeviceArray<T> energy_solid, energy_ice, laplacian, lambda;
  DeviceArray<Vec3<T>> active_x;
  neighbors::NeighborList bf;
  std::int64_t ice_count = 0;
  // Nucleation delay (freezing.freeze_delay > 0 only): fluid, seconds above a freezing threshold.
  bool nucleation_delay = false;
  DeviceArray<T> contact_time;

  /// Keeps the water particles order[0..count) in that order: every persistent per-water attribute
  /// (the state a checkpoint carries) is listed here and only here.
  void GatherFluid(const exec::Device& device, Index count);

  Index n() const { return static_cast<Index>(x.size()); }
  Index nb() const { return static_cast<Index>(bx.size()); }
  Pairs<T> FF() const { return {ff.offsets.data(), ff.indices.data(), ff_w.data(), ff_grad.data()}; }
  Pairs<T> FB() const { return {fb.offsets.data(), fb.indices.data(), fb_w.data(), fb_grad.data()}; }
};

namespace {

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

template <class V>
void Reorder(const exec::Device& device, DeviceArray<V>& array, DeviceArray<V>& scratch, const std::uint32_t* order, Index n) {
  scratch.resize(n);
  exec::ParallelFor(device, n, kernels::Gather<V>{array.data(), order, scratch.data()});
  array.swap(scratch);
}

template <class T>
Vec3<T> ToT(const Vec3d& v) {
  return {T(v.x), T(v.y), T(v.z)};
}

// Indices i < n with flags[i] != 0, in increasing order; returns their count.
Index ListFlagged(const exec::Device& device, const DeviceArray<std::uint32_t>& flags, Index n, DeviceArray<std::uint32_t>& slot,
                  DeviceArray<std::uint32_t>& list) {
  slot.resize(n);
  const Index count = static_cast<Index>(exec::ExclusiveScan(device, flags.data(), slot.data(), n));
  list.resize(count);
  if (count) exec::ParallelFor(device, n, kernels::CompactionOrder{flags.data(), slot.data(), list.data()});
  return count;
}

template <class V>
void Append(const exec::Device& device, DeviceArray<V>& array, const std::vector<V>& values) {
  const std::size_t n = array.size();
  array.resize(n + values.size());
  exec::CopyToDevice(device, array.data() + n, values.data(), values.size() * sizeof(V));
}

template <class T>
freeze::FreezeParams<T> MakeFreezeParams(const io::Scene& scene) {
  const io::FreezingSettings& f = scene.freezing;
  freeze::FreezeParams<T> p{};
  p.h = T(scene.fluid.smoothing_length());
  p.mass = T(scene.fluid.particle_mass());
  p.film_max = T(f.film_max_ratio * scene.fluid.particle_mass());
  p.alpha_solid = T(f.alpha_solid);
  p.alpha_ice = T(f.alpha_ice);
  p.dt_ref = T(f.dt_ref);
  p.glaze_threshold = T(f.glaze_threshold);
  p.icicle_threshold = T(f.icicle_threshold);
  p.growth_sign = T(f.growth_sign);
  p.gravity_growth = T(f.gravity_growth);
  const double g = Norm(scene.solver.gravity);
  p.gravity_dir = g > 0 && scene.Enabled("gravity") ? ToT<T>(scene.solver.gravity / g) : Vec3<T>{};
  p.fr_clamp = f.fr_mode == "clamp";
  p.ce_raw = f.ce_mode == "raw";
  p.ce_sum = f.ce_aggregation == "sum";
  p.isotropic = f.growth == "isotropic";
  p.pca.k_s = T(f.k_s);
  p.pca.k_r = T(f.k_r);
  p.pca.k_n = T(f.k_n);
  p.pca.n_eps = f.n_eps;
  p.pca.s_min = T(f.s_min);
  p.pca.s_max = T(f.s_max);
  p.pca.center_on_particle = f.pca_center == "particle";
  return p;
}

// Where a scene value came from, for error messages: "file: field", or the field alone for scenes
// built in code.
std::string SceneField(const io::Scene& scene, const std::string& field) {
  return scene.file.empty() ? field : scene.file.string() + ": " + field;
}

// The largest step the explicit non-pressure forces allow, and the scene parameter that sets it
// (empty when nothing limits). The pressure solve is implicit and the wall viscosity is solved
// per particle, so only these bind:
//   Monaghan viscosity Δt ν/h² ≤ 0.1 with ν = β0 β1 h/10 (spec §5.2); Morris Δt μ/(ρ0 h²) ≤ 0.1;
//   surface tension Δt ≤ 0.25 √(h/a) with a ≈ κ/(ρ0 h³) (He 2014) or a ≈ γ ρ0 (Akinci 2013).
std::pair<double, std::string> ExplicitStepLimit(const io::Scene& scene, const ModuleRegistry& modules) {
  double limit = 1e30;
  std::string parameter;
  auto bound = [&](double dt, const char* name) {
    if (dt < limit) limit = dt, parameter = name;
  };
  const double h = scene.fluid.smoothing_length(), rho0 = scene.fluid.rest_density;
  if (modules.Enabled("viscosity")) {
    const double nu = scene.viscosity.beta0 * scene.viscosity.beta1 * h / 10;
    if (nu > 0) bound(0.1 * h * h / nu, "viscosity.beta0");
    if (scene.viscosity.mu > 0) bound(0.1 * h * h * rho0 / scene.viscosity.mu, "viscosity.mu");
  }
  if (modules.Enabled("surface_tension")) {
    const io::SurfaceTensionSettings& st = scene.surface_tension;
    if (st.model == "akinci2013") {
      const double g = std::max(st.gamma, st.beta);
      if (g > 0) bound(0.25 * std::sqrt(h / (g * rho0)), st.gamma >= st.beta ? "surface_tension.gamma" : "surface_tension.beta");
    } else {
      const double kappa = std::max(st.kappa, st.kappa_boundary);
      if (kappa > 0) bound(0.25 * std::sqrt(rho0 * h * h * h * h / kappa), st.kappa >= st.kappa_boundary ? "surface_tension.kappa" : "surface_tension.kappa_boundary");
    }
  }
  return {limit, parameter};
}

}  // namespace

template <class T>
void Simulation<T>::State::GatherFluid(const exec::Device& device, Index count) {
  // The density is recomputed every step, but a frame written after particles froze or left must
  // carry the solver's values of the water that stayed.
  if (density.size() == x.size()) Reorder(device, density, tmp_scalar, order.data(), count);
  Reorder(device, x, tmp_vec, order.data(), count);
  Reorder(device, v, tmp_vec, order.data(), count);
  Reorder(device, pressure_previous, tmp_scalar, order.data(), count);
  Reorder(device, id, tmp_id, order.data(), count);
  if (nucleation_delay) Reorder(device, contact_time, tmp_scalar, order.data(), count);
}

template <class T>
Simulation<T>::Simulation(const io::Scene& scene, const exec::Device& device)
    : scene_(scene), device_(device), state_(std::make_unique<State>(device)) {
  for (const std::string& m : scene.modules) modules_.Enable(m);
  modules_.RecordAttribute("core", "position");
  modules_.RecordAttribute("core", "velocity");
  modules_.RecordAttribute("core", "density");
  modules_.RecordAttribute("core", "pressure");
  if (modules_.Enabled("surface_tension")) {
    if (scene.surface_tension.model == "akinci2013") {
      modules_.RecordAttribute("surface_tension", "surface_normal");
    } else {
      modules_.RecordAttribute("surface_tension", "color");
      modules_.RecordAttribute("surface_tension", "color_energy");
    }
  }
  if (modules_.Enabled("freezing")) {
    if (scene.freezing.pca != "w2h")
      throw InputError("freezing.pca = \"yu_turk\" (4h neighbourhood) is not implemented yet; use \"w2h\"", scene.file.string() + ": freezing.pca");
    for (const char* a : {"water_film", "growth_direction", "ice_kind", "ice_time", "ice_anisotropy", "fluid_anisotropy"})
      modules_.RecordAttribute("freezing", a);
  }
  emitter_travel_.assign(scene.emitters.size(), 0.0);
}

template <class T>
Simulation<T>::~Simulation() = default;

template <class T>
std::int64_t Simulation<T>::fluid_count() const {
  return state_->n();
}
template <class T>
std::int64_t Simulation<T>::ice_count() const {
  return state_->ice_count;
}
template <class T>
std::int64_t Simulation<T>::boundary_count() const {
  return state_->nb();
}

template <class T>
void Simulation<T>::AddBoundaryObject(const io::ParticleFrame& boundary, const std::string& object_name) {
  if (initialized_) throw Error(ExitCode::kFailure, "AddBoundaryObject after Initialize");
  State& s = *state_;
  const auto positions = boundary.GetPositions<T>();
  const std::uint32_t object = static_cast<std::uint32_t>(object_names_.size());
  object_names_.push_back(object_name);
  // The object's motion comes from the scene solid of the same name (static when none).
  ObjectMotion motion;
  for (const io::SolidObject& solid : scene_.solids)
    if (solid.name == object_name) motion = ObjectMotion(solid);
  s.any_animated = s.any_animated || motion.animated();
  s.object_motions.push_back(motion);

  std::vector<Vec3<T>> bx = s.bx.ToHost();
  std::vector<std::uint32_t> bobject = s.bobject.ToHost();
  std::vector<std::uint8_t> bphase = s.bphase.ToHost();
  std::vector<std::int64_t> bid = s.bid.ToHost();
  // Normals tell sealed tanks (inward-facing) from solids when water is placed (Initialize).
  std::vector<Vec3d> normals(positions.size());
  if (boundary.HasVec3("normal")) {
    const bool single = std::holds_alternative<std::vector<float>>(boundary.attributes.at("normal_0"));
    if (single) {
      const auto n = boundary.GetVec3<float>("normal");
      for (std::size_t i = 0; i < n.size(); ++i) normals[i] = {n[i].x, n[i].y, n[i].z};
    } else {
      normals = boundary.GetVec3<double>("normal");
    }
  }
  s.initial_normals.insert(s.initial_normals.end(), normals.begin(), normals.end());
  for (const Vec3<T>& p : positions) {
    if (!IsFinite(p)) throw InputError("boundary particle position is NaN or infinite", boundary.source);
    bx.push_back(p);
    bobject.push_back(object);
    bphase.push_back(static_cast<std::uint8_t>(io::Phase::kBoundary));
    bid.push_back(-static_cast<std::int64_t>(bid.size()) - 1);
  }
  s.bx.assign(bx);
  s.blocal.assign(bx);
  s.bobject.assign(bobject);
  s.bphase.assign(bphase);
  s.bid.assign(bid);
  s.bv.resize(bx.size());
  s.bv.SetZero();
}

template <class T>
void Simulation<T>::RecomputeBoundaryVolumes() {
  State& s = *state_;
  s.bvol.resize(s.nb());
  s.bpsi.resize(s.nb());
  boundary::ComputeBoundaryVolumes<T>(device_, s.bx.data(), s.nb(), T(scene_.fluid.smoothing_length()), s.bvol.data());
  FinishBoundaryVolumes();
}

static_assert(freeze::kIcePhase == std::uint8_t(io::Phase::kIce), "device kernels and files must agree on the ice phase");

template <class T>
void Simulation<T>::FinishBoundaryVolumes() {
  State& s = *state_;
  const double dp = scene_.fluid.spacing;
  if (s.ice_count > 0) exec::ParallelFor(device_, s.nb(), kernels::CapIceVolume<T>{s.bphase.data(), T(dp * dp * dp), s.bvol.data()});
  exec::ParallelFor(device_, s.nb(), kernels::Scale<T>{s.bvol.data(), T(scene_.fluid.rest_density), s.bpsi.data()});
}

template <class T>
void Simulation<T>::UpdateBoundaryMotion(double t) {
  State& s = *state_;
  if (!s.any_animated || s.nb() == 0) return;
  std::vector<RigidMotion<T>> motions;
  for (const ObjectMotion& m : s.object_motions) motions.push_back(m.At<T>(t));
  s.motions.assign(motions);
  exec::ParallelFor(device_, s.nb(), kernels::MoveBoundary<T>{s.blocal.data(), s.bobject.data(), s.motions.data(), s.bx.data(), s.bv.data()});
  s.boundary_grid.Build(s.bx.data(), s.nb(), T(2 * scene_.fluid.smoothing_length()), lattice_origin_);
}

template <class T>
void Simulation<T>::Initialize() {
  State& s = *state_;
  const double dp = scene_.fluid.spacing;
  const T support = T(2 * scene_.fluid.smoothing_length());
  {
    const auto [limit, parameter] = ExplicitStepLimit(scene_, modules_);
    if (scene_.solver.time_step == "cfl" && limit < scene_.solver.dt_min)
      throw InputError(fmt::format("{} needs time steps below {:.3g} s for stability, but simulation.dt_min is {:.3g} s: lower {} or dt_min",
                                   parameter, limit, scene_.solver.dt_min, parameter),
                       SceneField(scene_, parameter));
    if (scene_.solver.time_step == "fixed" && scene_.solver.dt > limit)
      log::Warn("simulation.dt = {:.3g} s exceeds the stability limit {:.3g} s set by {}: expect the run to diverge", scene_.solver.dt, limit,
                parameter);
  }
  UpdateBoundaryMotion(0.0);
  // Cells enclosed by closed solids, from the boundary particles at t = 0 (before they are reordered).
  std::vector<Vec3d> boundary_at_start;
  for (const Vec3<T>& p : s.bx.ToHost()) boundary_at_start.push_back({double(p.x), double(p.y), double(p.z)});
  const Enclosure enclosure(boundary_at_start, s.initial_normals, dp);
  boundary_at_start = {};
  s.initial_normals = {};
  for (std::size_t e = 0; e < scene_.emitters.size(); ++e)
    if (enclosure.Inside(scene_.emitters[e].center))
      throw InputError(fmt::format("emitter {}'s nozzle centre ({}, {}, {}) lies inside a closed solid: its water would be simulated inside the object",
                                   e + 1, scene_.emitters[e].center.x, scene_.emitters[e].center.y, scene_.emitters[e].center.z),
                       SceneField(scene_, "emitter.center"));
  if (s.nb() > 0) {
    // Order boundary particles along the Z curve once (cache locality), then compute Akinci volumes.
    s.boundary_grid.Build(s.bx.data(), s.nb(), support);
    DeviceArray<std::uint32_t> d_order(device_);
    d_order.resize(s.nb());
    exec::CopyOnDevice(device_, d_order.data(), s.boundary_grid.order(), s.nb() * sizeof(std::uint32_t));
    DeviceArray<Vec3<T>> tv(device_);
    DeviceArray<std::uint32_t> tu(device_);
    DeviceArray<std::uint8_t> t8(device_);
    DeviceArray<std::int64_t> ti(device_);
    Reorder(device_, s.bx, tv, d_order.data(), s.nb());
    Reorder(device_, s.blocal, tv, d_order.data(), s.nb());
    Reorder(device_, s.bv, tv, d_order.data(), s.nb());
    Reorder(device_, s.bobject, tu, d_order.data(), s.nb());
    Reorder(device_, s.bphase, t8, d_order.data(), s.nb());
    Reorder(device_, s.bid, ti, d_order.data(), s.nb());
    s.boundary_grid.AdoptOrder(s.bx.data());
    RecomputeBoundaryVolumes();
  } else {
    s.boundary_grid.Build(s.bx.data(), 0, support);
  }

  // Fluid blocks on a lattice of spacing d_p, anchored at the block's min corner (box) or centre
  // (sphere). Particles closer than 1.05 d_p to a boundary particle are dropped: fluid must start
  // about 1.1 d_p from walls (spec §3), and nothing may start inside a solid.
  std::vector<Vec3<T>> x;
  std::vector<Vec3<T>> v;
  for (const io::FluidBlock& block : scene_.fluid_blocks) {
    if (block.shape == "box") {
      const Vec3d ext = block.max - block.min;
      const std::int64_t nx = std::int64_t(std::floor(ext.x / dp + 1e-6)) + 1, ny = std::int64_t(std::floor(ext.y / dp + 1e-6)) + 1,
                         nz = std::int64_t(std::floor(ext.z / dp + 1e-6)) + 1;
      if (nx * ny * nz > 200'000'000) throw InputError("water block would create more than 200 million particles", SceneField(scene_, "water_block"));
      for (std::int64_t k = 0; k < nz; ++k)
        for (std::int64_t j = 0; j < ny; ++j)
          for (std::int64_t i = 0; i < nx; ++i) {
            x.push_back(ToT<T>(block.min + Vec3d(i * dp, j * dp, k * dp)));
            v.push_back(ToT<T>(block.velocity));
          }
    } else {
      const std::int64_t r = std::int64_t(std::floor(block.radius / dp + 1e-6));
      for (std::int64_t k = -r; k <= r; ++k)
        for (std::int64_t j = -r; j <= r; ++j)
          for (std::int64_t i = -r; i <= r; ++i) {
            const Vec3d offset(i * dp, j * dp, k * dp);
            if (Norm(offset) > block.radius + 1e-9) continue;
            x.push_back(ToT<T>(block.center + offset));
            v.push_back(ToT<T>(block.velocity));
          }
    }
  }
  std::size_t dropped = 0, enclosed = 0;
  if (enclosure.enclosed_cells() > 0) {
    std::vector<Vec3<T>> kept_x, kept_v;
    for (std::size_t i = 0; i < x.size(); ++i)
      if (!enclosure.Inside({double(x[i].x), double(x[i].y), double(x[i].z)})) kept_x.push_back(x[i]), kept_v.push_back(v[i]);
    enclosed = x.size() - kept_x.size();
    x.swap(kept_x);
    v.swap(kept_v);
  }
  if (enclosed) log::Warn("dropped {} water particles inside closed solids", enclosed);
  if (!x.empty() && s.nb() > 0) {
    DeviceArray<Vec3<T>> candidates(device_, x);
    neighbors::NeighborList near(device_);
    s.boundary_grid.Query(candidates.data(), Index(x.size()), T(1.05 * dp), false, near);
    const auto offsets = near.offsets.ToHost();
    std::vector<Vec3<T>> kept_x, kept_v;
    for (std::size_t i = 0; i < x.size(); ++i)
      if (offsets[i + 1] == offsets[i]) {
        kept_x.push_back(x[i]);
        kept_v.push_back(v[i]);
      }
    dropped = x.size() - kept_x.size();
    x.swap(kept_x);
    v.swap(kept_v);
  }
  if (dropped) log::Info("dropped {} water particles closer than 1.05 spacings to a solid", dropped);
  if constexpr (std::is_same_v<T, float>) {
    // Single precision resolves 2^-23 of a coordinate: 10 km from the origin that is 1.2 mm, too
    // coarse for centimetre particles. Refuse rather than simulate silently wrong motion.
    double far = 0;
    for (const Vec3<T>& p : x) far = std::max({far, std::fabs(double(p.x)), std::fabs(double(p.y)), std::fabs(double(p.z))});
    for (const Vec3<T>& p : s.bx.ToHost()) far = std::max({far, std::fabs(double(p.x)), std::fabs(double(p.y)), std::fabs(double(p.z))});
    const double resolution = far * std::ldexp(1.0, -23);
    if (resolution > 0.01 * dp)
      throw InputError(fmt::format("the scene reaches {:.4g} m from the origin, where single precision resolves only {:.3g} m ({:.2g} particle "
                                   "spacings): set water.precision = \"double\" or move the scene near the origin",
                                   far, resolution, resolution / dp),
                       SceneField(scene_, "water.precision"));
  }
  if (!scene_.fluid_blocks.empty() && x.empty() && scene_.emitters.empty())
    throw InputError("every water particle lies inside or against a solid: nothing to simulate", SceneField(scene_, "water_block"));
  std::vector<std::int64_t> ids(x.size());
  for (auto& id : ids) id = next_id_++;
  s.x.assign(x);
  s.v.assign(v);
  s.id.assign(ids);
  s.pressure_previous.resize(x.size());
  s.pressure_previous.SetZero();
  ComputeDomain(x);
  // One cell lattice for the water and boundary grids, so that neighbor searches run cell by cell.
  {
    Vec3<T> lo = domain_min_;
    for (const Vec3<T>& p : BoundaryPositions()) lo = Min(lo, p);
    lattice_origin_ = {std::floor(lo.x / support) * support - support, std::floor(lo.y / support) * support - support,
                       std::floor(lo.z / support) * support - support};
    if (s.nb() > 0) s.boundary_grid.Build(s.bx.data(), s.nb(), support, lattice_origin_);
  }
  if (modules_.Enabled("freezing")) {
    for (auto* a : {&s.growth_valid, &s.ice_kind}) {
      a->resize(s.nb());
      a->SetZero();
    }
    s.film.resize(s.nb());
    s.film.SetZero();
    s.growth.resize(s.nb());
    s.growth.SetZero();
    s.ice_time.resize(s.nb());
    s.ice_time.SetZero();
    s.ice_d.resize(s.nb());
    s.ice_d.SetZero();
    s.nucleation_delay = scene_.freezing.freeze_delay > 0;
    if (s.nucleation_delay) {
      s.contact_time.resize(s.n());
      s.contact_time.SetZero();
    }
  }
  initialized_ = true;
}

template <class T>
void Simulation<T>::Freeze(double dt) {
  State& s = *state_;
  const Index n = s.n(), nb = s.nb();
  if (n == 0 || nb == 0) return;
  modules_.CountLaunch("freezing");
  const freeze::FreezeParams<T> p = MakeFreezeParams<T>(scene_);
  const CubicSpline<T> kernel(p.h);
  const T support = kernel.SupportRadius();
  namespace fk = freeze::kernels;

  // Who touches whom: fluid with boundary neighbors, and boundary particles with fluid neighbors
  // (their B–F lists at the new positions, spec §11 step 8).
  s.fluid_flag.resize(n);
  s.boundary_active.resize(nb);
  s.boundary_active.SetZero();
  exec::ParallelFor(device_, n, fk::MarkContacts<T>{s.fb.offsets.data(), s.fb.indices.data(), s.fluid_flag.data(), s.boundary_active.data()});
  const Index active = ListFlagged(device_, s.boundary_active, nb, s.slot, s.active_list);
  s.active_x.resize(active);
  exec::ParallelFor(device_, active, kernels::Gather<Vec3<T>>{s.bx.data(), s.active_list.data(), s.active_x.data()});
  s.fluid_grid.Query(s.active_x.data(), active, support, false, s.bf);
  exec::ParallelFor(device_, active, fk::MarkFluidFromBoundary{s.bf.offsets.data(), s.bf.indices.data(), s.fluid_flag.data()});

  // 8a fluid anisotropy, 8b film transfer + 8d growth direction.
  s.fluid_d.resize(n);
  exec::ParallelFor(device_, n, fk::FluidAnisotropy<T>{s.fluid_flag.data(), s.ff.offsets.data(), s.ff.indices.data(), s.x.data(), kernel, p, s.fluid_d.data()});
  exec::ParallelFor(device_, active,
                    fk::FilmAndGrowth<T>{s.active_list.data(), s.bf.offsets.data(), s.bf.indices.data(), s.bx.data(), s.bvol.data(),
                                         s.bphase.data(), s.x.data(), s.v.data(), s.fluid_d.data(), kernel, p, T(dt), s.film.data(),
                                         s.growth.data(), s.growth_valid.data()});
  if (scene_.freezing.drying_rate > 0)
    exec::ParallelFor(device_, nb, fk::DryFilm<T>{T(std::exp(-scene_.freezing.drying_rate * dt)), s.film.data()});

  // 8c film diffusion over the wet region and its one-ring. Operator splitting: the diffusion
  // time accumulates until one explicit step of it would use half the stability budget (the
  // plane reference λ h² ≈ 5, spec §9.3), then it is applied with its accumulated time step and
  // sub-stepped if the actual λ_max needs it. At small Δt this saves most diffusion passes.
  const double diffusivity = scene_.freezing.film_diffusion * scene_.fluid.spacing * scene_.fluid.spacing / scene_.freezing.dt_ref;
  diffusion_pending_ += dt;
  const double h = scene_.fluid.smoothing_length();
  if (diffusivity > 0 && diffusion_pending_ * diffusivity * 5.0 / (h * h) >= 0.5) {
    const double dt_diffusion = diffusion_pending_;
    diffusion_pending_ = 0;
    s.wet.resize(nb);
    s.region.resize(nb);
    s.region.SetZero();
    exec::ParallelFor(device_, nb, fk::MarkWet<T>{s.film.data(), s.wet.data()});
    exec::ParallelFor(device_, nb, fk::DilateWet<T>{s.boundary_grid.view(), s.wet.data(), support, s.region.data()});
    const Index region = ListFlagged(device_, s.region, nb, s.slot, s.region_list);
    if (region > 0) {
      s.laplacian.resize(region);
      s.lambda.resize(region);
      const fk::FilmLaplacian<T> laplacian{s.region_list.data(), s.boundary_grid.view(), s.bvol.data(), s.film.data(), kernel,
                                           T(scene_.viscosity.epsilon), s.laplacian.data(), s.lambda.data()};
      exec::ParallelFor(device_, region, laplacian);
      const double lambda_max = exec::Max(device_, s.lambda.data(), region);
      const int substeps = std::max(1, int(std::ceil(dt_diffusion * diffusivity * lambda_max)));
      for (int sub = 0; sub < substeps; ++sub) {
        if (sub > 0) exec::ParallelFor(device_, region, laplacian);
        exec::ParallelFor(device_, region,
                          fk::ApplyFilmDiffusion<T>{s.region_list.data(), s.laplacian.data(), T(dt_diffusion * diffusivity / substeps), s.film.data()});
      }
    }
  }

  // 8e decisions from one snapshot, 8f conversions applied together.
  for (auto* a : {&s.decision, &s.trigger, &s.keep, &s.frozen}) a->resize(n);
  s.energy_solid.resize(n);
  s.energy_ice.resize(n);
  exec::ParallelFor(device_, n,
                    fk::PhaseDecision<T>{s.fb.offsets.data(), s.fb.indices.data(), s.x.data(), s.fluid_d.data(), s.bx.data(), s.bphase.data(),
                                         s.film.data(), s.growth.data(), s.growth_valid.data(), kernel, p, s.decision.data(), s.trigger.data(),
                                         s.energy_solid.data(), s.energy_ice.data()});
  if (s.nucleation_delay)
    exec::ParallelFor(device_, n, fk::NucleationDelay<T>{T(dt), T(scene_.freezing.freeze_delay), s.decision.data(), s.contact_time.data()});
  exec::ParallelFor(device_, n, fk::KeepUnfrozen{s.decision.data(), s.keep.data(), s.frozen.data()});
  DeviceArray<std::uint32_t> frozen_list(device_);
  const Index frozen = ListFlagged(device_, s.frozen, n, s.slot, frozen_list);
  if (frozen > 0) ConvertToIce(frozen_list, frozen, time_ + dt);
}

template <class T>
void Simulation<T>::ConvertToIce(const DeviceArray<std::uint32_t>& frozen_list, Index frozen, double when) {
  State& s = *state_;
  const Index n = s.n();
  // Gather what the new ice needs (few particles per step: the host does the bookkeeping).
  DeviceArray<Vec3<T>> fx(device_, frozen);
  DeviceArray<std::uint32_t> kind(device_, frozen), trig(device_, frozen), object(device_, frozen);
  DeviceArray<std::int64_t> ids(device_, frozen);
  DeviceArray<freeze::Sym6<T>> d(device_, frozen);
  const std::uint32_t* list = frozen_list.data();
  exec::ParallelFor(device_, frozen, kernels::Gather<Vec3<T>>{s.x.data(), list, fx.data()});
  exec::ParallelFor(device_, frozen, kernels::Gather<std::uint32_t>{s.decision.data(), list, kind.data()});
  exec::ParallelFor(device_, frozen, kernels::Gather<std::uint32_t>{s.trigger.data(), list, trig.data()});
  exec::ParallelFor(device_, frozen, kernels::Gather<std::uint32_t>{s.bobject.data(), trig.data(), object.data()});
  exec::ParallelFor(device_, frozen, kernels::Gather<std::int64_t>{s.id.data(), list, ids.data()});
  exec::ParallelFor(device_, frozen, kernels::Gather<freeze::Sym6<T>>{s.fluid_d.data(), list, d.data()});
  const auto hx = fx.ToHost();
  const auto hkind = kind.ToHost();
  const auto hobject = object.ToHost();
  std::vector<Vec3<T>> local(frozen);
  for (Index k = 0; k < frozen; ++k) {
    // Ice is attached to the object it froze onto: store its rest-pose (local) position.
    Mat3<double> r;
    Vec3d t;
    s.object_motions[hobject[k]].Pose(time_, r, t);
    const Vec3d l = Transpose(r) * (Vec3d(hx[k]) - t);
    local[k] = ToT<T>(l);
  }
  std::vector<std::uint8_t> kinds(frozen);
  for (Index k = 0; k < frozen; ++k) kinds[k] = static_cast<std::uint8_t>(hkind[k]);
  Append(device_, s.bx, hx);
  Append(device_, s.blocal, local);
  Append(device_, s.bv, std::vector<Vec3<T>>(frozen));
  Append(device_, s.bobject, hobject);
  Append(device_, s.bphase, std::vector<std::uint8_t>(frozen, static_cast<std::uint8_t>(io::Phase::kIce)));
  Append(device_, s.bid, ids.ToHost());
  Append(device_, s.film, std::vector<T>(frozen, T(0)));
  Append(device_, s.growth, std::vector<Vec3<T>>(frozen));
  Append(device_, s.growth_valid, std::vector<std::uint8_t>(frozen, 0));
  Append(device_, s.ice_kind, kinds);
  Append(device_, s.ice_time, std::vector<double>(frozen, when));
  Append(device_, s.ice_d, d.ToHost());
  s.ice_count += frozen;
  // Remove the frozen particles from the fluid.
  const Index kept = n - frozen;
  ListFlagged(device_, s.keep, n, s.slot, s.order);
  s.GatherFluid(device_, kept);
  // The boundary set changed: re-index it and recompute the volumes of every boundary particle
  // within 2h of new ice, the new ice included (spec §3, §9.7).
  const T support = T(2 * scene_.fluid.smoothing_length());
  s.boundary_grid.Build(s.bx.data(), s.nb(), support, lattice_origin_);
  s.bvol.resize(s.nb());
  s.bpsi.resize(s.nb());
  neighbors::NeighborList near(device_);
  s.boundary_grid.Query(fx.data(), frozen, support, false, near);
  s.region.resize(s.nb());
  s.region.SetZero();
  exec::ParallelFor(device_, frozen, kernels::MarkListed{near.offsets.data(), near.indices.data(), s.region.data()});
  const Index dirty = ListFlagged(device_, s.region, s.nb(), s.slot, s.region_list);
  exec::ParallelFor(device_, dirty, boundary::kernels::BoundaryVolume<T>{s.boundary_grid.view(), CubicSpline<T>(support / 2), s.bvol.data(),
                                                                          s.region_list.data()});
  FinishBoundaryVolumes();
}

template <class T>
void Simulation<T>::ComputeDomain(const std::vector<Vec3<T>>& fluid) {
  if (scene_.domain.set) {
    domain_min_ = ToT<T>(scene_.domain.min);
    domain_max_ = ToT<T>(scene_.domain.max);
    return;
  }
  // Default: the bounding box of solids, water and emitters, enlarged by max(1 m, half its size).
  Vec3d lo = Vec3d::Splat(1e300), hi = Vec3d::Splat(-1e300);
  auto grow = [&](const Vec3d& p) { lo = Min(lo, p), hi = Max(hi, p); };
  for (const Vec3<T>& p : BoundaryPositions()) grow(Vec3d(p));
  for (const Vec3<T>& p : fluid) grow(Vec3d(p));
  for (const io::Emitter& e : scene_.emitters) grow(e.center);
  if (lo.x > hi.x) lo = hi = Vec3d{};
  const Vec3d margin = Max(Vec3d::Splat(1.0), (hi - lo) * 0.5);
  domain_min_ = ToT<T>(lo - margin);
  domain_max_ = ToT<T>(hi + margin);
}

template <class T>
double Simulation<T>::NextTimeStep(double next_stop) const {
  const io::SolverSettings& solver = scene_.solver;
  double dt = solver.dt;
  if (solver.time_step == "cfl") {
    const State& s = *state_;
    double max_speed = 0;
    if (s.n() > 0) {
      DeviceArray<T> speed2(device_, s.n());
      exec::ParallelFor(device_, s.n(), kernels::SquaredSpeed<T>{s.v.data(), speed2.data()});
      max_speed = std::sqrt(double(exec::Max(device_, speed2.data(), s.n())));
    }
    // Head speed √(2 g H), H = the fluid's extent along gravity: the speed its own weight can give
    // it. Without it, deep water at rest steps at dt_max, and the pressure displacements Δt² p/(ρ d_p)
    // of the bottom layers reach a spacing (a 0.5 m column at d_p = 12.5 mm diverged at 6 ms).
    const double g = Norm(scene_.solver.gravity);
    if (s.n() > 0 && g > 0 && modules_.Enabled("gravity")) {
      DeviceArray<T> heights(device_, 2 * s.n());
      exec::ParallelFor(device_, s.n(), kernels::Heights<T>{s.x.data(), ToT<T>(scene_.solver.gravity / -g), s.n(), heights.data()});
      const double top = double(exec::Max(device_, heights.data(), s.n()));
      const double bottom = -double(exec::Max(device_, heights.data() + s.n(), s.n()));
      max_speed = std::max(max_speed, std::sqrt(2 * g * (top - bottom)));
    }
    for (const io::Emitter& e : scene_.emitters) max_speed = std::max(max_speed, e.speed);
    dt = max_speed > 0 ? solver.cfl * scene_.fluid.spacing / max_speed : solver.dt_max;
    // Initialize refused a scene whose explicit limit lies below dt_min, so clamping keeps it.
    dt = std::clamp(std::min(dt, ExplicitStepLimit(scene_, modules_).first), solver.dt_min, solver.dt_max);
  }
  // Equal steps up to the stop, none longer than dt: the step then stays the same from frame to
  // frame for water at rest. A shortened step at every stop (the remainder, or half of it) jolted
  // resting water at each output frame (Iisph.OutputFramesDoNotJoltWaterAtRest). Likely why: with
  // spec §6's default a_ii, water next to walls stays compressed, and the pressure the solve keeps
  // on it scales with 1/Δt², so a sudden change of Δt unbalances it.
  const double remaining = next_stop - time_;
  const double steps = std::ceil(remaining / dt * (1 - 1e-9));
  return steps > 1 ? remaining / steps : std::max(remaining, 1e-12);
}

template <class T>
void Simulation<T>::NeighborSearch() {
  State& s = *state_;
  const Index n = s.n();
  const T support = T(2 * scene_.fluid.smoothing_length());
  s.fluid_grid.Build(s.x.data(), n, support, lattice_origin_);
  // Reorder the persistent fluid state along the grid's Z curve for cache locality.
  s.order.resize(n);
  exec::CopyOnDevice(device_, s.order.data(), s.fluid_grid.order(), n * sizeof(std::uint32_t));
  s.GatherFluid(device_, n);
  s.fluid_grid.AdoptOrder(s.x.data());

  const CubicSpline<T> kernel(T(scene_.fluid.smoothing_length()));
  s.fluid_grid.QueryGrid(s.fluid_grid, support, true, s.ff);
  s.ff_w.resize(s.ff.pairs());
  s.ff_grad.resize(s.ff.pairs());
  exec::ParallelFor(device_, n, kernels::PairValues<T>{s.x.data(), s.x.data(), s.ff.offsets.data(), s.ff.indices.data(), kernel, s.ff_w.data(), s.ff_grad.data()});
  s.boundary_grid.QueryGrid(s.fluid_grid, support, false, s.fb);
  s.fb_w.resize(s.fb.pairs());
  s.fb_grad.resize(s.fb.pairs());
  exec::ParallelFor(device_, n, kernels::PairValues<T>{s.x.data(), s.bx.data(), s.fb.offsets.data(), s.fb.indices.data(), kernel, s.fb_w.data(), s.fb_grad.data()});
}

template <class T>
double Simulation<T>::ComputeDensity() {
  State& s = *state_;
  const Index n = s.n();
  s.density.resize(n);
  s.density_error.resize(n);
  const CubicSpline<T> kernel(T(scene_.fluid.smoothing_length()));
  exec::ParallelFor(device_, n, kernels::Density<T>{s.FF(), s.FB(), s.bpsi.data(), T(scene_.fluid.particle_mass()), kernel.W0(),
                                                     T(scene_.fluid.rest_density), s.density.data(), s.density_error.data()});
  s.scratch.resize(n);
  exec::ParallelFor(device_, n, kernels::Compression<T>{s.density_error.data(), s.scratch.data()});
  return exec::Sum(device_, s.scratch.data(), n) / double(n) / scene_.fluid.rest_density;
}

template <class T>
void Simulation<T>::NonPressureAccelerations(double dt) {
  State& s = *state_;
  const Index n = s.n();
  const T mass = T(scene_.fluid.particle_mass());
  const T h = T(scene_.fluid.smoothing_length());
  s.accel.resize(n);
  const Vec3<T> gravity = modules_.Enabled("gravity") ? ToT<T>(scene_.solver.gravity) : Vec3<T>{};
  exec::ParallelFor(device_, n, kernels::InitAcceleration<T>{gravity, s.accel.data()});
  if (modules_.Enabled("viscosity")) {
    const io::ViscositySettings& vs = scene_.viscosity;
    exec::ParallelFor(device_, n, kernels::ViscosityAcceleration<T>{s.FF(), s.x.data(), s.v.data(), s.density.data(), mass, T(vs.mu),
                                                                     T(vs.beta0 * vs.beta1), h, T(vs.epsilon), vs.limiter, s.accel.data()});
    modules_.CountLaunch("viscosity");
  }
  if (modules_.Enabled("surface_tension") && scene_.surface_tension.model == "akinci2013") {
    const io::SurfaceTensionSettings& st = scene_.surface_tension;
    const T support = T(2) * h;
    s.surface_normal.resize(n);
    exec::ParallelFor(device_, n, kernels::AkinciNormal<T>{s.FF(), s.density.data(), mass, support, s.surface_normal.data()});
    exec::ParallelFor(device_, n,
                      kernels::AkinciSurfaceTensionAcceleration<T>{s.FF(), s.FB(), s.x.data(), s.bx.data(), s.density.data(),
                                                                   s.surface_normal.data(), s.bpsi.data(), mass, T(st.gamma), T(st.beta),
                                                                   T(scene_.fluid.rest_density), support, s.accel.data()});
    modules_.CountLaunch("surface_tension");
  } else if (modules_.Enabled("surface_tension")) {
    const CubicSpline<T> kernel(h);
    s.color.resize(n);
    s.energy.resize(n);
    exec::ParallelFor(device_, n, kernels::SurfaceColor<T>{s.FF(), s.FB(), s.density.data(), s.bvol.data(), mass, kernel.W0(), s.color.data()});
    exec::ParallelFor(device_, n, kernels::SurfaceEnergy<T>{s.FF(), s.density.data(), s.color.data(), mass, s.energy.data()});
    exec::ParallelFor(device_, n,
                      kernels::SurfaceTensionAcceleration<T>{s.FF(), s.FB(), s.density.data(), s.energy.data(), s.bvol.data(), mass,
                                                             T(scene_.surface_tension.kappa), T(scene_.surface_tension.kappa_boundary),
                                                             s.accel.data()});
    modules_.CountLaunch("surface_tension");
  }
  if (modules_.Enabled("air_pressure")) {
    exec::ParallelFor(device_, n, kernels::AirPressureAcceleration<T>{s.FF(), s.FB(), s.density.data(), s.bvol.data(), mass,
                                                                       T(scene_.air_pressure.p_atm), s.accel.data()});
    modules_.CountLaunch("air_pressure");
  }
  s.v_adv.resize(n);
  const bool wall_viscosity = modules_.Enabled("viscosity");
  const T wall_coefficient = wall_viscosity ? T(scene_.viscosity.wall_beta0 * scene_.viscosity.beta1) : T(0);
  exec::ParallelFor(device_, n,
                    kernels::AdvectVelocity<T>{s.v.data(), s.accel.data(), T(dt), s.FB(), s.x.data(), s.bx.data(), s.bv.data(),
                                               s.bpsi.data(), s.density.data(), wall_coefficient, h, T(scene_.viscosity.epsilon),
                                               T(scene_.fluid.rest_density), scene_.viscosity.limiter, CubicSpline<T>(h), s.FF(),
                                               s.pressure_previous.data(), mass, s.v_adv.data()});
}

template <class T>
StepStats Simulation<T>::SolvePressure(double dt, double omega) {
  State& s = *state_;
  const Index n = s.n();
  const io::SolverSettings& solver = scene_.solver;
  const T mass = T(scene_.fluid.particle_mass());
  const T h = T(scene_.fluid.smoothing_length());
  const double rho0 = scene_.fluid.rest_density;
  for (auto* a : {&s.advected_error, &s.a_ii, &s.pressure, &s.pressure_next, &s.compression}) a->resize(n);
  s.d_ii.resize(n);
  s.s.resize(n);
  const T chi = solver.aii_boundary == "splishsplash" ? T(1) : T(0);
  exec::ParallelFor(device_, n,
                    kernels::PredictAdvection<T>{s.FF(), s.FB(), s.v_adv.data(), s.bv.data(), s.bpsi.data(), s.density.data(),
                                                 s.density_error.data(), s.pressure_previous.data(), mass, T(dt), chi, T(solver.warm_start),
                                                 s.d_ii.data(), s.advected_error.data(), s.a_ii.data(), s.pressure.data()});
  // ε_a = 1e-6 Δt²/h² (spec §6): below it a particle is (nearly) isolated and gets p = 0.
  const T min_aii = T(1e-6 * dt * dt / (double(h) * double(h)));
  StepStats stats;
  stats.dt = dt;
  double previous_error = INFINITY;
  int growth_streak = 0;
  for (int l = 0; l < solver.max_iterations; ++l) {
    exec::ParallelFor(device_, n, kernels::DisplacementSum<T>{s.FF(), s.pressure.data(), s.density.data(), mass, T(dt), s.s.data()});
    exec::ParallelFor(device_, n,
                      kernels::PressureUpdate<T>{s.FF(), s.FB(), s.s.data(), s.d_ii.data(), s.a_ii.data(), s.pressure.data(),
                                                 s.density.data(), s.advected_error.data(), s.bpsi.data(), mass, T(dt), T(omega),
                                                 min_aii, s.pressure_next.data(), s.compression.data()});
    s.pressure.swap(s.pressure_next);
    const double error = exec::Sum(device_, s.compression.data(), n) / double(n) / rho0;
    stats.pressure_iterations = l + 1;
    stats.average_density_error = error;
    if (!std::isfinite(error)) break;
    if (error <= solver.eta && l + 1 >= solver.min_iterations) {
      stats.converged = true;
      return stats;
    }
    growth_streak = error > previous_error ? growth_streak + 1 : 0;
    previous_error = error;
    if (growth_streak >= 3 && omega > 0.5 && solver.omega_fallback) {
      // Weighted Jacobi with ω = 0.8 can diverge (spec §6): restart this step's solve with 0.5.
      StepStats retry = SolvePressure(dt, 0.5);
      retry.omega_fallback = true;
      retry.pressure_iterations += stats.pressure_iterations;
      return retry;
    }
  }
  stats.converged = false;
  return stats;
}

template <class T>
void Simulation<T>::Integrate(double dt) {
  State& s = *state_;
  exec::ParallelFor(device_, s.n(),
                    kernels::IntegratePressure<T>{s.FF(), s.FB(), s.pressure.data(), s.density.data(), s.bpsi.data(), s.v_adv.data(),
                                                  T(scene_.fluid.particle_mass()), T(dt), s.v.data(), s.x.data(),
                                                  s.pressure_previous.data()});
}

template <class T>
void Simulation<T>::RemoveOutsideDomain(StepStats& stats) {
  State& s = *state_;
  const Index n = s.n();
  if (n == 0) return;
  s.keep.resize(n);
  s.slot.resize(n);
  exec::ParallelFor(device_, n, kernels::InsideDomain<T>{s.x.data(), domain_min_, domain_max_, s.keep.data()});
  const Index kept = ListFlagged(device_, s.keep, n, s.slot, s.order);
  if (kept == n) return;
  s.GatherFluid(device_, kept);
  stats.removed_particles = n - kept;
  removed_total_ += n - kept;
}

template <class T>
void Simulation<T>::Emit(double dt, StepStats& stats) {
  State& s = *state_;
  const double dp = scene_.fluid.spacing;
  std::vector<Vec3<T>> new_x, new_v;
  for (std::size_t e = 0; e < scene_.emitters.size(); ++e) {
    const io::Emitter& em = scene_.emitters[e];
    // Active part of [time, time + dt) within [start, stop).
    const double t0 = std::max(time_, em.start), t1 = std::min(time_ + dt, em.stop);
    if (t1 <= t0) continue;
    emitter_travel_[e] += em.speed * (t1 - t0);
    const Vec3d dir = em.direction / Norm(em.direction);
    const Vec3d helper = std::fabs(dir.z) < 0.9 ? Vec3d(0, 0, 1) : Vec3d(1, 0, 0);
    const Vec3d u = Cross(dir, helper) / Norm(Cross(dir, helper));
    const Vec3d w = Cross(dir, u);
    const double half_u = em.shape == "disc" ? em.radius : em.width / 2;
    const double half_w = em.shape == "disc" ? em.radius : em.height / 2;
    const std::int64_t nu = std::int64_t(std::floor(half_u / dp + 1e-9)), nw = std::int64_t(std::floor(half_w / dp + 1e-9));
    while (emitter_travel_[e] >= dp) {
      emitter_travel_[e] -= dp;
      // The layer emitted `travel` ago has moved that far already.
      const Vec3d base = em.center + dir * emitter_travel_[e];
      for (std::int64_t a = -nu; a <= nu; ++a)
        for (std::int64_t b = -nw; b <= nw; ++b) {
          if (em.shape == "disc" && std::hypot(a * dp, b * dp) > em.radius + 1e-9) continue;
          new_x.push_back(ToT<T>(base + u * (a * dp) + w * (b * dp)));
          new_v.push_back(ToT<T>(dir * em.speed));
        }
    }
  }
  if (new_x.empty()) return;
  const Index n = s.n(), m = Index(new_x.size());
  std::vector<std::int64_t> ids(m);
  for (auto& id : ids) id = next_id_++;
  s.x.resize(n + m);
  s.v.resize(n + m);
  s.id.resize(n + m);
  s.pressure_previous.resize(n + m);  // new particles start with p = 0
  if (s.nucleation_delay) s.contact_time.resize(n + m);
  exec::CopyToDevice(device_, s.x.data() + n, new_x.data(), m * sizeof(Vec3<T>));
  exec::CopyToDevice(device_, s.v.data() + n, new_v.data(), m * sizeof(Vec3<T>));
  exec::CopyToDevice(device_, s.id.data() + n, ids.data(), m * sizeof(std::int64_t));
  stats.emitted_particles = m;
}

// Largest displacement per step, in particle spacings, before a step is reported as diverged.
constexpr double kMaxSpacingsPerStep = 0.8;

template <class T>
void Simulation<T>::CheckDivergence(const StepStats& stats) const {
  const double limit = scene_.solver.divergence_density_error;
  const bool bad_error = !std::isfinite(stats.average_density_error) || stats.average_density_error > limit;
  const bool bad_speed = !std::isfinite(stats.max_speed);
  // A particle crossing more than 0.8 spacings in one step can tunnel through single-layer walls
  // (measured: 0.7 holds, 0.8 leaks); spec §7 steps at 0.4, and scene files allow cfl ≤ 0.7.
  const double courant = stats.max_speed * stats.dt / scene_.fluid.spacing;
  const bool bad_courant = courant > kMaxSpacingsPerStep;
  if (!bad_error && !bad_speed && !bad_courant) return;
  // Name the worst particle: a non-finite one, else the fastest.
  const auto x = Positions();
  const auto v = Velocities();
  const auto ids = Ids();
  std::size_t worst = 0;
  double worst_speed = -1;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double sp = double(Norm(v[i]));
    if (!IsFinite(x[i]) || !std::isfinite(sp)) {
      worst = i;
      break;
    }
    if (sp > worst_speed) worst_speed = sp, worst = i;
  }
  std::string particle = x.empty() ? "no particles"
                                   : fmt::format("worst particle id {} at ({:.4g}, {:.4g}, {:.4g}) m, speed {:.4g} m/s", ids[worst],
                                                 double(x[worst].x), double(x[worst].y), double(x[worst].z), double(Norm(v[worst])));
  const std::string reason = bad_speed     ? "a particle velocity became NaN or infinite"
                             : bad_courant ? fmt::format("particles move {:.3g} spacings per step (above {}, where they tunnel through walls): the time step is too large",
                                                         courant, kMaxSpacingsPerStep)
                                           : fmt::format("average density error {:.3g}% exceeds the limit {:.3g}% (simulation.divergence_density_error)",
                                                     100 * stats.average_density_error, 100 * limit);
  const char* advice = scene_.solver.time_step == "fixed" ? "Reduce simulation.dt" : "Reduce simulation.cfl or dt_max";
  throw Error(ExitCode::kDiverged, fmt::format("simulation diverged at step {} (t = {:.6g} s, dt = {:.3g} s): {}; {}. {}, or check the scene",
                                               step_count_, time_, stats.dt, reason, particle, advice));
}

template <class T>
StepStats Simulation<T>::Step(double dt) {
  if (!initialized_) throw Error(ExitCode::kFailure, "Step before Initialize");
  State& s = *state_;
  StepStats stats;
  {
    PhaseTimer t(device_, timing_enabled_, timings_.other);
    Emit(dt, stats);
    UpdateBoundaryMotion(time_);
  }
  if (s.n() == 0) {
    time_ += dt;
    ++step_count_;
    stats.dt = dt;
    return stats;
  }
  {
    PhaseTimer t(device_, timing_enabled_, timings_.neighbor_search);
    NeighborSearch();
  }
  double measured_error = 0;
  {
    PhaseTimer t(device_, timing_enabled_, timings_.non_pressure);
    measured_error = ComputeDensity();
    NonPressureAccelerations(dt);
  }
  StepStats solve;
  {
    PhaseTimer t(device_, timing_enabled_, timings_.pressure_solve);
    solve = SolvePressure(dt, scene_.solver.omega);
  }
  solve.emitted_particles = stats.emitted_particles;
  stats = solve;
  stats.measured_density_error = measured_error;
  {
    PhaseTimer t(device_, timing_enabled_, timings_.integration);
    Integrate(dt);
    stats.max_density_error = s.n() ? exec::Max(device_, s.compression.data(), s.n()) / scene_.fluid.rest_density : 0;
    s.scratch.resize(s.n());
    exec::ParallelFor(device_, s.n(), kernels::SquaredSpeed<T>{s.v.data(), s.scratch.data()});
    stats.max_speed = std::sqrt(double(exec::Max(device_, s.scratch.data(), s.n())));
  }
  CheckDivergence(stats);
  if (modules_.Enabled("freezing")) {
    PhaseTimer t(device_, timing_enabled_, timings_.freezing);
    const std::int64_t before = state_->ice_count;
    Freeze(dt);
    stats.frozen_particles = state_->ice_count - before;
  }
  time_ += dt;
  ++step_count_;
  RemoveOutsideDomain(stats);
  stats.fluid_particles = s.n();
  return stats;
}

template <class T>
std::size_t Simulation<T>::MemoryBytes() const {
  const State& s = *state_;
  std::size_t bytes = 0;
  for (const auto* a : {&s.x, &s.v, &s.v_adv, &s.accel, &s.d_ii, &s.s, &s.bx, &s.bv, &s.blocal, &s.ff_grad, &s.fb_grad, &s.tmp_vec, &s.surface_normal}) bytes += a->bytes();
  for (const auto* a : {&s.density, &s.density_error, &s.pressure, &s.pressure_next, &s.pressure_previous, &s.advected_error, &s.a_ii,
                        &s.compression, &s.scratch, &s.color, &s.energy, &s.bpsi, &s.bvol, &s.ff_w, &s.fb_w, &s.tmp_scalar, &s.contact_time})
    bytes += a->bytes();
  bytes += s.ff.offsets.bytes() + s.ff.indices.bytes() + s.fb.offsets.bytes() + s.fb.indices.bytes();
  return bytes;
}

template <class T> std::vector<Vec3<T>> Simulation<T>::Positions() const { return state_->x.ToHost(); }
template <class T> std::vector<Vec3<T>> Simulation<T>::Velocities() const { return state_->v.ToHost(); }
template <class T> std::vector<T> Simulation<T>::Densities() const { return state_->density.ToHost(); }
template <class T> std::vector<T> Simulation<T>::Pressures() const { return state_->pressure_previous.ToHost(); }
template <class T> std::vector<std::int64_t> Simulation<T>::Ids() const { return state_->id.ToHost(); }
template <class T> std::vector<Vec3<T>> Simulation<T>::BoundaryPositions() const { return state_->bx.ToHost(); }
template <class T> std::vector<T> Simulation<T>::BoundaryVolumes() const { return state_->bvol.ToHost(); }
template <class T> std::vector<Vec3<T>> Simulation<T>::NonPressureAccelerations() const { return state_->accel.ToHost(); }

template <class T>
void Simulation<T>::SetFluidState(const std::vector<Vec3<T>>& x, const std::vector<Vec3<T>>& v) {
  State& s = *state_;
  if (x.size() != v.size()) throw Error(ExitCode::kFailure, "SetFluidState: size mismatch");
  const bool resized = Index(x.size()) != s.n();
  s.x.assign(x);
  s.v.assign(v);
  if (resized) {
    std::vector<std::int64_t> ids(x.size());
    for (auto& id : ids) id = next_id_++;
    s.id.assign(ids);
    s.pressure_previous.resize(x.size());
    s.pressure_previous.SetZero();
    if (s.nucleation_delay) {
      s.contact_time.resize(x.size());
      s.contact_time.SetZero();
    }
  }
  initialized_ = true;
}

template <class T>
io::ParticleFrame Simulation<T>::Snapshot(std::int64_t frame_number) const {
  const State& s = *state_;
  io::ParticleFrame f;
  f.kind = "particles";
  f.time = time_;
  f.frame = frame_number;
  f.spacing = scene_.fluid.spacing;
  f.particle_radius = scene_.fluid.spacing / 2;
  f.rest_density = scene_.fluid.rest_density;
  f.scene_hash = scene_.hash;
  f.numbers["smoothing_length"] = scene_.fluid.smoothing_length();
  f.numbers["step_count"] = double(step_count_);
  f.numbers["next_id"] = double(next_id_);
  f.numbers["removed_total"] = double(removed_total_);
  f.numbers["precision_bits"] = double(sizeof(T) * 8);
  f.numbers["water_particles"] = double(s.n());
  f.numbers["film_diffusion_pending"] = diffusion_pending_;
  for (std::size_t e = 0; e < emitter_travel_.size(); ++e) f.numbers[fmt::format("emitter_travel_{}", e)] = emitter_travel_[e];
  f.texts["modules"] = fmt::format("{}", fmt::join(modules_.enabled(), ","));

  // Water first; with freezing on, every boundary particle follows (solids carry the film state,
  // ice its anisotropy), so that a frame is a complete checkpoint and the surface stage finds ice.
  const bool freezing = modules_.Enabled("freezing");
  std::vector<Vec3<T>> x = s.x.ToHost(), v = s.v.ToHost();
  std::vector<std::int64_t> id = s.id.ToHost();
  std::vector<std::uint8_t> phase(x.size(), static_cast<std::uint8_t>(io::Phase::kFluid));
  std::vector<T> pressure = s.pressure_previous.ToHost();
  std::vector<T> density = s.density.size() == x.size() ? s.density.ToHost() : std::vector<T>(x.size(), T(scene_.fluid.rest_density));
  if (freezing) {
    f.numbers["ice_particles"] = double(s.ice_count);
    f.numbers["film_max"] = scene_.freezing.film_max_ratio * scene_.fluid.particle_mass();
    const std::size_t nf = x.size(), nb = s.nb();
    const auto bx = s.bx.ToHost(), bv = s.bv.ToHost(), local = s.blocal.ToHost(), growth = s.growth.ToHost();
    const auto bphase = s.bphase.ToHost();
    const auto bid = s.bid.ToHost();
    const auto bvol = s.bvol.ToHost(), film = s.film.ToHost();
    const auto bobject = s.bobject.ToHost();
    const auto valid = s.growth_valid.ToHost(), kind = s.ice_kind.ToHost();
    const auto ice_time = s.ice_time.ToHost();
    const auto ice_d = s.ice_d.ToHost();
    x.insert(x.end(), bx.begin(), bx.end());
    v.insert(v.end(), bv.begin(), bv.end());
    id.insert(id.end(), bid.begin(), bid.end());
    phase.insert(phase.end(), bphase.begin(), bphase.end());
    pressure.resize(nf + nb, T(0));
    density.resize(nf + nb, T(scene_.fluid.rest_density));
    std::vector<T> volume(nf + nb, T(0)), water_film(nf + nb, T(0));
    std::vector<std::uint32_t> object(nf + nb, 0);
    std::vector<std::uint8_t> growth_valid(nf + nb, 0), ice_kind(nf + nb, 0);
    std::vector<double> created(nf + nb, 0);
    std::vector<Vec3<T>> growth_dir(nf + nb), local_all(nf + nb);
    std::vector<T> aniso[6];
    for (auto& a : aniso) a.assign(nf + nb, T(0));
    for (std::size_t b = 0; b < nb; ++b) {
      volume[nf + b] = bvol[b];
      water_film[nf + b] = film[b];
      object[nf + b] = bobject[b];
      growth_valid[nf + b] = valid[b];
      ice_kind[nf + b] = kind[b];
      created[nf + b] = ice_time[b];
      growth_dir[nf + b] = growth[b];
      local_all[nf + b] = local[b];
      for (int c = 0; c < 6; ++c) aniso[c][nf + b] = ice_d[b].c[c];
    }
    f.Set("volume", std::move(volume));
    f.Set("water_film", std::move(water_film));
    f.Set("object_id", std::move(object));
    f.Set("growth_valid", std::move(growth_valid));
    f.Set("ice_kind", std::move(ice_kind));
    f.Set("ice_time", std::move(created));
    f.SetVec3("growth_dir", growth_dir);
    f.SetVec3("local", local_all);
    for (int c = 0; c < 6; ++c) f.Set(fmt::format("anisotropy_{}", c), std::move(aniso[c]));
    if (s.nucleation_delay) {
      std::vector<T> contact = s.contact_time.ToHost();
      contact.resize(nf + nb, T(0));
      f.Set("contact_time", std::move(contact));
    }
  }
  f.SetPositions(x);
  std::vector<T> vx(v.size()), vy(v.size()), vz(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) vx[i] = v[i].x, vy[i] = v[i].y, vz[i] = v[i].z;
  f.Set("vx", std::move(vx));
  f.Set("vy", std::move(vy));
  f.Set("vz", std::move(vz));
  f.Set("id", std::move(id));
  f.Set("phase", std::move(phase));
  f.Set("pressure", std::move(pressure));
  f.Set("density", std::move(density));
  return f;
}

template <class T>
void Simulation<T>::Restore(const io::ParticleFrame& f) {
  if (!initialized_) Initialize();
  State& s = *state_;
  const auto bits = f.numbers.find("precision_bits");
  if (bits == f.numbers.end() || bits->second != double(sizeof(T) * 8))
    throw InputError(fmt::format("checkpoint precision does not match the scene's water.precision = \"{}\"", scene_.fluid.precision), f.source);
  if (std::fabs(f.spacing - scene_.fluid.spacing) > 1e-12 * scene_.fluid.spacing)
    throw InputError("checkpoint was written with a different water.spacing", f.source);
  auto number = [&](const std::string& key) {
    const auto it = f.numbers.find(key);
    if (it == f.numbers.end()) throw InputError("checkpoint lacks the attribute '" + key + "'", f.source);
    return it->second;
  };
  time_ = f.time;
  step_count_ = std::int64_t(number("step_count"));
  next_id_ = std::int64_t(number("next_id"));
  removed_total_ = std::int64_t(number("removed_total"));
  diffusion_pending_ = number("film_diffusion_pending");
  for (std::size_t e = 0; e < emitter_travel_.size(); ++e) emitter_travel_[e] = number(fmt::format("emitter_travel_{}", e));
  const auto x = f.GetPositions<T>();
  const auto& phase = f.Get<std::uint8_t>("phase");
  const auto& vx = f.Get<T>("vx");
  const auto& vy = f.Get<T>("vy");
  const auto& vz = f.Get<T>("vz");
  const auto& id = f.Get<std::int64_t>("id");
  const auto& pressure = f.Get<T>("pressure");
  const auto& density = f.Get<T>("density");
  std::vector<Vec3<T>> fx, fv;
  std::vector<std::int64_t> fid;
  const std::vector<T>* contact = s.nucleation_delay ? &f.Get<T>("contact_time") : nullptr;
  std::vector<T> fp, fd, fc;
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (phase[i] != static_cast<std::uint8_t>(io::Phase::kFluid)) continue;
    fx.push_back(x[i]);
    fv.push_back({vx[i], vy[i], vz[i]});
    fid.push_back(id[i]);
    fp.push_back(pressure[i]);
    fd.push_back(density[i]);
    if (contact) fc.push_back((*contact)[i]);
  }
  s.x.assign(fx);
  s.v.assign(fv);
  s.id.assign(fid);
  s.pressure_previous.assign(fp);
  s.density.assign(fd);
  if (contact) s.contact_time.assign(fc);
  if (modules_.Enabled("freezing")) {
    // Solids keep their order (Initialize reorders them the same way); ice is appended in order.
    const auto& film = f.Get<T>("water_film");
    const auto& valid = f.Get<std::uint8_t>("growth_valid");
    const auto& kind = f.Get<std::uint8_t>("ice_kind");
    const auto& created = f.Get<double>("ice_time");
    const auto& object = f.Get<std::uint32_t>("object_id");
    const auto growth = f.GetVec3<T>("growth_dir");
    const auto local = f.GetVec3<T>("local");
    std::vector<const std::vector<T>*> aniso;
    for (int c = 0; c < 6; ++c) aniso.push_back(&f.Get<T>(fmt::format("anisotropy_{}", c)));
    auto hfilm = s.film.ToHost();
    auto hgrowth = s.growth.ToHost();
    auto hvalid = s.growth_valid.ToHost();
    std::size_t solid = 0;
    std::vector<Vec3<T>> ix, il;
    std::vector<std::uint32_t> io_;
    std::vector<std::int64_t> iid;
    std::vector<T> ifilm;
    std::vector<Vec3<T>> igrowth;
    std::vector<std::uint8_t> ivalid, ikind;
    std::vector<double> itime;
    std::vector<freeze::Sym6<T>> id6;
    // Akinci volumes as the run had them: a run updates them only within 2h of new ice, with another
    // summation order than a full recomputation, so recomputing them would not resume bit-identically.
    const std::vector<T>* volume = f.attributes.count("volume") ? &f.Get<T>("volume") : nullptr;
    std::vector<T> solid_volume, ice_volume;
    for (std::size_t i = 0; i < x.size(); ++i) {
      if (phase[i] == static_cast<std::uint8_t>(io::Phase::kBoundary)) {
        if (solid >= hfilm.size()) throw InputError("checkpoint holds more solid particles than the boundary files", f.source);
        if (volume) solid_volume.push_back((*volume)[i]);
        hfilm[solid] = film[i];
        hgrowth[solid] = growth[i];
        hvalid[solid] = valid[i];
        ++solid;
      } else if (phase[i] == static_cast<std::uint8_t>(io::Phase::kIce)) {
        ix.push_back(x[i]);
        if (volume) ice_volume.push_back((*volume)[i]);
        il.push_back(local[i]);
        io_.push_back(object[i]);
        iid.push_back(id[i]);
        ifilm.push_back(film[i]);
        igrowth.push_back(growth[i]);
        ivalid.push_back(valid[i]);
        ikind.push_back(kind[i]);
        itime.push_back(created[i]);
        freeze::Sym6<T> d;
        for (int c = 0; c < 6; ++c) d.c[c] = (*aniso[c])[i];
        id6.push_back(d);
      }
    }
    if (solid != hfilm.size()) throw InputError("checkpoint and boundary files disagree on the number of solid particles", f.source);
    s.film.assign(hfilm);
    s.growth.assign(hgrowth);
    s.growth_valid.assign(hvalid);
    if (!ix.empty()) {
      Append(device_, s.bx, ix);
      Append(device_, s.blocal, il);
      Append(device_, s.bv, std::vector<Vec3<T>>(ix.size()));
      Append(device_, s.bobject, io_);
      Append(device_, s.bphase, std::vector<std::uint8_t>(ix.size(), static_cast<std::uint8_t>(io::Phase::kIce)));
      Append(device_, s.bid, iid);
      Append(device_, s.film, ifilm);
      Append(device_, s.growth, igrowth);
      Append(device_, s.growth_valid, ivalid);
      Append(device_, s.ice_kind, ikind);
      Append(device_, s.ice_time, itime);
      Append(device_, s.ice_d, id6);
      s.ice_count = Index(ix.size());
      s.boundary_grid.Build(s.bx.data(), s.nb(), T(2 * scene_.fluid.smoothing_length()), lattice_origin_);
      if (volume) {
        solid_volume.insert(solid_volume.end(), ice_volume.begin(), ice_volume.end());
        s.bvol.assign(solid_volume);
        s.bpsi.resize(s.nb());
        FinishBoundaryVolumes();
      } else {
        RecomputeBoundaryVolumes();
      }
    }
  }
  UpdateBoundaryMotion(time_);
}

template class Simulation<float>;
template class Simulation<double>;

}  // namespace rime::sph
