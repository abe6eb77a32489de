// The cleanup chain (see rime/clean/clean.h). Every CGAL call of rime-clean is in this one
// translation unit: CGAL headers take minutes to compile.
//
// Costs measured with CGAL 5.5.1 on a closed 438k-triangle mesh, one thread (LIBRARY_NOTES.md):
// soup repair on load 2.2 s, isotropic remeshing 3.9 s per pass, angle smoothing 2.1 s, tangential
// relaxation 0.3 s, Garland-Heckbert decimation to half 2.6 s. Hence the defaults: build the
// Surface_mesh directly (soup repair only as a fallback), no remeshing, tangential relaxation,
// and decimation by rime's own batched collapse (decimate.cpp; CGAL's stays selectable).
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/angle_and_area_smoothing.h>
#include <CGAL/Polygon_mesh_processing/border.h>
#include <CGAL/Polygon_mesh_processing/compute_normal.h>
#include <CGAL/Polygon_mesh_processing/connected_components.h>
#include <CGAL/Polygon_mesh_processing/manifoldness.h>
#include <CGAL/Polygon_mesh_processing/orient_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/orientation.h>
#include <CGAL/Polygon_mesh_processing/polygon_soup_to_polygon_mesh.h>
#include <CGAL/Polygon_mesh_processing/remesh.h>
#include <CGAL/Polygon_mesh_processing/repair.h>
#include <CGAL/Polygon_mesh_processing/repair_degeneracies.h>
#include <CGAL/Polygon_mesh_processing/repair_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/repair_self_intersections.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Polygon_mesh_processing/smooth_shape.h>
#include <CGAL/Polygon_mesh_processing/tangential_relaxation.h>
#include <CGAL/Polygon_mesh_processing/triangulate_hole.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/GarlandHeckbert_plane_policies.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <tuple>

#include "rime/core/cpu_time.h"
#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/clean/clean.h"
#include "rime/clean/decimate.h"

namespace rime::clean {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Mesh = CGAL::Surface_mesh<Point>;
using VertexIndex = Mesh::Vertex_index;
using FaceIndex = Mesh::Face_index;
using HalfedgeIndex = Mesh::Halfedge_index;
namespace PMP = CGAL::Polygon_mesh_processing;
namespace SMS = CGAL::Surface_mesh_simplification;
namespace params = CGAL::parameters;

bool RepeatsVertex(const std::array<std::uint32_t, 3>& t) { return t[0] == t[1] || t[1] == t[2] || t[0] == t[2]; }

/// Adds the triangles as they are; returns how many could not be added without breaking
/// manifoldness (Surface_mesh refuses them).
std::size_t BuildDirect(const io::TriMesh& in, Mesh& mesh, std::size_t& repeated_vertex_faces) {
  mesh.clear();
  mesh.reserve(Mesh::size_type(in.positions.size()), Mesh::size_type(in.triangles.size() * 3 / 2), Mesh::size_type(in.triangles.size()));
  for (const Vec3f& p : in.positions) mesh.add_vertex(Point(p.x, p.y, p.z));
  std::size_t refused = 0;
  for (const auto& t : in.triangles) {
    if (RepeatsVertex(t)) {
      ++repeated_vertex_faces;
      continue;
    }
    if (mesh.add_face(VertexIndex(t[0]), VertexIndex(t[1]), VertexIndex(t[2])) == Mesh::null_face()) ++refused;
  }
  PMP::remove_isolated_vertices(mesh);
  return refused;
}

/// CGAL's soup repair: merges duplicate points, drops degenerate and duplicate polygons, orients
/// consistently (duplicating the points of non-manifold vertices and edges), then builds the mesh.
/// Returns false when the soup could not be oriented without such duplications.
bool BuildFromSoup(const io::TriMesh& in, Mesh& mesh) {
  std::vector<Point> points;
  points.reserve(in.positions.size());
  for (const Vec3f& p : in.positions) points.emplace_back(p.x, p.y, p.z);
  std::vector<std::vector<std::size_t>> polygons;
  polygons.reserve(in.triangles.size());
  for (const auto& t : in.triangles) polygons.push_back({t[0], t[1], t[2]});
  PMP::repair_polygon_soup(points, polygons);
  const bool oriented = PMP::orient_polygon_soup(points, polygons);
  mesh.clear();
  PMP::polygon_soup_to_polygon_mesh(points, polygons, mesh);
  PMP::duplicate_non_manifold_vertices(mesh);
  return oriented;
}

/// True when two border vertices share a position: an unwelded mesh (e.g. one triangle per STL
/// facet), whose faces only the soup repair joins.
bool BorderVerticesShareAPosition(const Mesh& mesh) {
  std::vector<std::array<double, 4>> border;  // x, y, z, vertex index
  for (HalfedgeIndex h : mesh.halfedges())
    if (mesh.is_border(h)) {
      const Point& p = mesh.point(mesh.target(h));
      border.push_back({p.x(), p.y(), p.z(), double(std::uint32_t(mesh.target(h)))});
    }
  std::sort(border.begin(), border.end());
  for (std::size_t i = 1; i < border.size(); ++i)
    if (border[i][0] == border[i - 1][0] && border[i][1] == border[i - 1][1] && border[i][2] == border[i - 1][2] &&
        border[i][3] != border[i - 1][3])
      return true;
  return false;
}

bool HasBorder(const Mesh& mesh) {
  for (HalfedgeIndex h : mesh.halfedges())
    if (mesh.is_border(h)) return true;
  return false;
}

/// Faces, area, signed volume and closedness of each connected component (fcc: face -> component).
struct ComponentMeasures {
  std::vector<std::size_t> faces;
  std::vector<double> area, volume;
  std::vector<char> closed;
};
template <typename ComponentMap>
ComponentMeasures MeasureComponents(const Mesh& mesh, const ComponentMap& fcc, std::size_t count) {
  ComponentMeasures m{std::vector<std::size_t>(count, 0), std::vector<double>(count, 0), std::vector<double>(count, 0),
                      std::vector<char>(count, 1)};
  for (FaceIndex f : mesh.faces()) {
    const std::size_t c = fcc[f];
    ++m.faces[c];
    const HalfedgeIndex h = mesh.halfedge(f);
    const Point &a = mesh.point(mesh.source(h)), &b = mesh.point(mesh.target(h)), &p = mesh.point(mesh.target(mesh.next(h)));
    m.area[c] += std::sqrt(CGAL::to_double(CGAL::squared_area(a, b, p)));
    m.volume[c] += CGAL::to_double(CGAL::scalar_product(a - CGAL::ORIGIN, CGAL::cross_product(b - CGAL::ORIGIN, p - CGAL::ORIGIN))) / 6;
  }
  for (HalfedgeIndex h : mesh.halfedges())
    if (mesh.is_border(h)) m.closed[fcc[mesh.face(mesh.opposite(h))]] = 0;
  return m;
}

double SignedVolume(const Mesh& mesh) {
  double volume = 0;
  for (FaceIndex f : mesh.faces()) {
    const HalfedgeIndex h = mesh.halfedge(f);
    const Point& a = mesh.point(mesh.source(h));
    const Point& b = mesh.point(mesh.target(h));
    const Point& c = mesh.point(mesh.target(mesh.next(h)));
    volume += CGAL::to_double(CGAL::scalar_product(a - CGAL::ORIGIN, CGAL::cross_product(b - CGAL::ORIGIN, c - CGAL::ORIGIN))) / 6;
  }
  return volume;
}

/// Faces of `mesh` that cross another face, pairs among `ignored` faces or touching the piece
/// `skip` left out. Sequential for the reason given in Chain::SelfIntersections.
template <typename ComponentMap>
std::vector<FaceIndex> CrossingFaces(const Mesh& mesh, const ComponentMap& fcc, std::size_t skip, const std::vector<char>& ignored) {
  std::vector<std::pair<FaceIndex, FaceIndex>> pairs;
  PMP::self_intersections<CGAL::Sequential_tag>(faces(mesh), mesh, std::back_inserter(pairs));
  std::vector<FaceIndex> crossing;
  for (const auto& [a, b] : pairs) {
    if (fcc[a] == skip || fcc[b] == skip) continue;
    if (!ignored.empty() && ignored[a] && ignored[b]) continue;
    crossing.push_back(a);
    crossing.push_back(b);
  }
  return crossing;
}

struct ShapeSmoothing {
  std::size_t kept_pieces = 0;      // pieces a step would have halved, left as they were
  std::size_t unfolded_places = 0;  // vertices put back where a step made two faces cross
};

/// CGAL's mean-curvature flow, `iterations` steps of `time` (m²), each closed piece's volume
/// restored after every step where the piece stands. Where a step makes faces cross (the two
/// sides of a thin sheet), their vertices go back to where the step found them and stay there.
ShapeSmoothing SmoothShapeKeepingPieces(Mesh& mesh, double time, int iterations) {
  auto fcc = mesh.add_property_map<FaceIndex, std::size_t>("f:rime_component", 0).first;
  auto fixed = mesh.add_property_map<VertexIndex, bool>("v:rime_fixed", false).first;
  const std::size_t count = PMP::connected_components(mesh, fcc);
  const std::vector<double> target = MeasureComponents(mesh, fcc, count).volume;
  // CGAL rescales the whole mesh about its centroid after each step unless two or more vertices
  // are constrained; a constrained tetrahedron (piece `count`, removed after) turns that off.
  const HalfedgeIndex anchor = CGAL::make_tetrahedron(Point(0, 0, 0), Point(1e-3, 0, 0), Point(0, 1e-3, 0), Point(0, 0, 1e-3), mesh);
  for (VertexIndex v : CGAL::vertices_around_face(anchor, mesh)) fixed[v] = true;
  fixed[mesh.target(mesh.next(mesh.opposite(anchor)))] = true;
  for (FaceIndex f : CGAL::faces_around_face(anchor, mesh)) fcc[f] = count;
  fcc[mesh.face(anchor)] = count;
  std::vector<std::size_t> vertex_component(mesh.num_vertices(), count);
  for (VertexIndex v : mesh.vertices()) {
    if (mesh.halfedge(v) == Mesh::null_halfedge()) continue;
    for (FaceIndex f : CGAL::faces_around_target(mesh.halfedge(v), mesh))
      if (f != Mesh::null_face()) vertex_component[v] = fcc[f];
  }
  std::vector<Point> start(mesh.num_vertices());
  ShapeSmoothing result;
  // Faces that crossed before the flow are not the flow's doing: only pairs with another face count.
  std::vector<char> crossed_before(mesh.num_faces(), 0);
  for (FaceIndex f : CrossingFaces(mesh, fcc, count, {})) crossed_before[f] = 1;
  // One step at a time, each piece's volume restored after it by offsetting the piece along
  // its normals (loss / area). A piece that one step shrinks by half or more is a bead the
  // flow collapses: it goes back to where the step found it and stays there.
  for (int it = 0; it < iterations; ++it) {
    for (VertexIndex v : mesh.vertices()) start[v] = mesh.point(v);
    PMP::smooth_shape(mesh, time, params::number_of_iterations(1).vertex_is_constrained_map(fixed));
    const ComponentMeasures now = MeasureComponents(mesh, fcc, count + 1);
    std::vector<double> offset(count + 1, 0);
    std::vector<char> collapsed(count + 1, 0);
    for (std::size_t c = 0; c < count; ++c) {
      if (!now.closed[c] || !(target[c] > 0)) continue;
      if (!(now.volume[c] > 0.5 * target[c]) || !(now.area[c] > 0)) collapsed[c] = 1;
      else offset[c] = (target[c] - now.volume[c]) / now.area[c];
    }
    std::vector<Kernel::Vector_3> move(mesh.num_vertices(), CGAL::NULL_VECTOR);
    for (VertexIndex v : mesh.vertices())
      if (offset[vertex_component[v]] != 0) move[v] = offset[vertex_component[v]] * PMP::compute_vertex_normal(v, mesh);
    for (VertexIndex v : mesh.vertices()) {
      if (fixed[v]) continue;
      if (collapsed[vertex_component[v]]) {
        mesh.point(v) = start[v];
        fixed[v] = true;
      } else {
        mesh.point(v) += move[v];
      }
    }
    result.kept_pieces += std::count(collapsed.begin(), collapsed.end(), 1);
    // Put back the crossing faces' vertices, then their neighbours' if that is not enough.
    for (int ring = 0; ring < 3; ++ring) {
      const std::vector<FaceIndex> crossing = CrossingFaces(mesh, fcc, count, crossed_before);
      if (crossing.empty()) break;
      std::vector<VertexIndex> back;
      for (FaceIndex f : crossing)
        for (VertexIndex v : CGAL::vertices_around_face(mesh.halfedge(f), mesh)) {
          back.push_back(v);
          if (ring > 0)
            for (VertexIndex u : CGAL::vertices_around_target(mesh.halfedge(v), mesh)) back.push_back(u);
        }
      for (VertexIndex v : back) {
        if (fixed[v]) continue;
        mesh.point(v) = start[v];
        fixed[v] = true;
        ++result.unfolded_places;
      }
    }
  }
  PMP::remove_connected_components(mesh, std::vector<std::size_t>{count}, fcc);
  mesh.remove_property_map(fcc);
  mesh.remove_property_map(fixed);
  mesh.collect_garbage();
  return result;
}

io::TriMesh ToTriMesh(Mesh& mesh) {
  mesh.collect_garbage();  // indices become 0..n-1
  io::TriMesh out;
  out.positions.reserve(mesh.number_of_vertices());
  for (VertexIndex v : mesh.vertices()) {
    const Point& p = mesh.point(v);
    out.positions.emplace_back(float(p.x()), float(p.y()), float(p.z()));
  }
  out.triangles.reserve(mesh.number_of_faces());
  for (FaceIndex f : mesh.faces()) {
    const HalfedgeIndex h = mesh.halfedge(f);
    out.triangles.push_back({std::uint32_t(mesh.source(h)), std::uint32_t(mesh.target(h)), std::uint32_t(mesh.target(mesh.next(h)))});
  }
  return out;
}

// Stops the edge collapse at a target edge count or when the cheapest collapse costs more than
// the error bound (the Garland-Heckbert cost is the quadric error: a sum of squared distances to
// the planes of the original faces around the collapsed edge, m^2).
struct DecimationStop {
  std::size_t target_edges;
  double max_cost;  // <= 0: no bound
  template <typename F, typename Profile, typename SizeType>
  bool operator()(const F& current_cost, const Profile&, SizeType, SizeType current_edges) const {
    return current_edges <= target_edges || (max_cost > 0 && CGAL::to_double(current_cost) > max_cost);
  }
};

class Chain {
 public:
  Chain(const io::CleanupSettings& s, CleanReport& r) : settings_(s), report_(r) {}

  template <class Body>
  void Run(const char* name, Body&& body) {
    const auto start = std::chrono::steady_clock::now();
    const double cpu_start = ProcessCpuSeconds();
    std::string detail = body();
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    log::Debug("{}: {} ({:.3f} s)", name, detail, seconds);
    report_.operations.push_back({name, seconds, ProcessCpuSeconds() - cpu_start, std::move(detail)});
  }

  void Load(const io::TriMesh& in) {
    Run("repair", [&] {
      std::size_t repeated = 0;
      bool soup = settings_.repair == io::Repair::kAlways;
      std::size_t refused = 0;
      if (!soup) {
        refused = BuildDirect(in, mesh_, repeated);
        // A few refused faces (a non-manifold edge here and there in marching-cubes output) are
        // dropped and their holes filled later: far cheaper than repairing the whole soup.
        const std::size_t tolerated = std::max<std::size_t>(16, in.triangles.size() / 1000);
        if (settings_.repair == io::Repair::kAuto && (refused > tolerated || BorderVerticesShareAPosition(mesh_))) soup = true;
      }
      std::string detail;
      if (soup) {
        const bool oriented = BuildFromSoup(in, mesh_);
        report_.repair_path = "soup";
        detail = fmt::format("polygon soup repair ({} faces were not manifold as given){}", refused,
                             oriented ? "" : "; some points were duplicated to orient the soup");
      } else {
        report_.repair_path = "direct";
        report_.faces_dropped_on_load = refused;
        report_.degenerate_faces_removed += repeated;
        const std::size_t split = PMP::duplicate_non_manifold_vertices(mesh_);
        detail = fmt::format(
            "built directly ({} faces with a repeated vertex skipped, {} non-manifold faces dropped, "
            "{} non-manifold vertices split)",
            repeated, refused, split);
        if (refused > 0 && settings_.repair == io::Repair::kNever)
          report_.warnings.push_back(fmt::format("{} non-manifold faces dropped on load (repair = \"never\")", refused));
      }
      // Orientation: outward normals for closed meshes. A soup may contain nested shells, which
      // orient_to_bound_a_volume handles; a directly built mesh only gets flipped as a whole.
      if (!HasBorder(mesh_) && !mesh_.is_empty()) {
        if (soup) {
          PMP::orient_to_bound_a_volume(mesh_);
          detail += ", oriented to bound a volume";
        } else if (SignedVolume(mesh_) < 0) {
          PMP::reverse_face_orientations(mesh_);
          detail += ", orientation reversed (inward normals)";
        }
      }
      return detail;
    });
  }

  void RemoveDegenerate() {
    if (!settings_.remove_degenerate && !settings_.remove_almost_degenerate) return;
    Run("degenerate", [&] {
      const std::size_t before = mesh_.number_of_faces();
      if (settings_.remove_degenerate) PMP::remove_degenerate_faces(mesh_);
      bool almost_ok = true;
      if (settings_.remove_almost_degenerate) {
        const double cap_cosine = std::cos(settings_.cap_angle_deg * std::numbers::pi / 180);
        // Only collapse edges no longer than the mean edge: keeps the collapses local.
        almost_ok = PMP::experimental::remove_almost_degenerate_faces(mesh_, cap_cosine, settings_.needle_ratio, MeanEdge());
      }
      mesh_.collect_garbage();
      const std::size_t removed = before - std::min(before, std::size_t(mesh_.number_of_faces()));
      report_.degenerate_faces_removed += removed;
      return fmt::format("{} faces removed{}", removed,
                         settings_.remove_almost_degenerate && !almost_ok ? " (some caps/needles remain)" : "");
    });
  }

  void RemoveSmallComponents() {
    if (!settings_.remove_components) return;
    Run("components", [&] {
      auto fcc = mesh_.add_property_map<FaceIndex, std::size_t>("f:rime_component", 0).first;
      const std::size_t count = PMP::connected_components(mesh_, fcc);
      const auto [faces, area, volume, closed] = MeasureComponents(mesh_, fcc, count);
      const std::size_t largest = count == 0 ? 0 : std::size_t(std::max_element(faces.begin(), faces.end()) - faces.begin());
      std::vector<std::size_t> remove;
      std::size_t removed_faces = 0;
      for (std::size_t c = 0; c < count; ++c) {
        const bool small = (settings_.min_component_faces > 0 && faces[c] < std::size_t(settings_.min_component_faces)) ||
                           (settings_.min_component_area > 0 && area[c] < settings_.min_component_area) ||
                           (settings_.min_component_volume > 0 && closed[c] && std::abs(volume[c]) < settings_.min_component_volume);
        if (small && c != largest) {  // the largest component always stays: a frame never vanishes
          remove.push_back(c);
          removed_faces += faces[c];
        }
      }
      if (!remove.empty()) PMP::remove_connected_components(mesh_, remove, fcc);
      mesh_.remove_property_map(fcc);
      mesh_.collect_garbage();
      report_.components_removed += remove.size();
      report_.component_faces_removed += removed_faces;
      return fmt::format("{} of {} components removed ({} faces)", remove.size(), count, removed_faces);
    });
  }

  void FillHoles() {
    if (!settings_.fill_holes) return;
    Run("holes", [&] {
      std::vector<HalfedgeIndex> cycles;
      PMP::extract_boundary_cycles(mesh_, std::back_inserter(cycles));
      std::size_t filled = 0, left = 0, failed_fairing = 0;
      for (HalfedgeIndex h : cycles) {
        if (!mesh_.is_border(h)) continue;
        std::size_t length = 0;
        HalfedgeIndex e = h;
        do {
          ++length;
          e = mesh_.next(e);
        } while (e != h && length <= std::size_t(settings_.max_hole_edges));
        if (length > std::size_t(settings_.max_hole_edges)) {
          ++left;
          continue;
        }
        std::vector<FaceIndex> new_faces;
        std::vector<VertexIndex> new_vertices;
        if (settings_.fair_holes) {
          const bool faired =
              std::get<0>(PMP::triangulate_refine_and_fair_hole(mesh_, h, std::back_inserter(new_faces), std::back_inserter(new_vertices)));
          if (!faired) ++failed_fairing;
        } else {
          PMP::triangulate_and_refine_hole(mesh_, h, std::back_inserter(new_faces), std::back_inserter(new_vertices));
        }
        if (new_faces.empty()) ++left;
        else ++filled;
      }
      report_.holes_filled += filled;
      report_.holes_left += left;
      return fmt::format("{} holes filled, {} left (over {} edges or unfillable){}", filled, left, settings_.max_hole_edges,
                         failed_fairing ? fmt::format(", fairing failed on {}", failed_fairing) : "");
    });
  }

  void Remesh(double mean_input_edge) {
    if (!settings_.remesh) return;
    Run("remesh", [&] {
      const double target = settings_.target_edge > 0 ? settings_.target_edge : settings_.target_edge_factor * mean_input_edge;
      report_.target_edge = target;
      if (!(target > 0) || mesh_.is_empty()) return std::string("skipped (no target edge length)");
      PMP::isotropic_remeshing(faces(mesh_), target, mesh_, params::number_of_iterations(settings_.remesh_iterations));
      mesh_.collect_garbage();
      return fmt::format("{} iteration(s) to edge {:.4g} m: {} faces", settings_.remesh_iterations, target, mesh_.number_of_faces());
    });
  }

  void Smooth() {
    if (settings_.smooth != io::MeshSmoothing::kNone && settings_.smooth_iterations > 0 && !mesh_.is_empty()) {
      Run("smooth", [&] {
        if (settings_.smooth == io::MeshSmoothing::kTangential) {
          PMP::tangential_relaxation(vertices(mesh_), mesh_, params::number_of_iterations(settings_.smooth_iterations));
        } else {
          // Area smoothing needs Ceres (absent here; CGAL would print a warning): angles only.
          // The safety check (no new self-intersection) halves the speed; it is kept.
          PMP::angle_and_area_smoothing(
              mesh_, params::number_of_iterations(settings_.smooth_iterations).use_angle_smoothing(true).use_area_smoothing(false));
        }
        return fmt::format("{} x {}", settings_.smooth_iterations, io::EnumName(settings_.smooth));
      });
    }
    if (settings_.shape_smooth_iterations > 0 && !mesh_.is_empty()) {
      Run("shape_smooth", [&] {
        const ShapeSmoothing done = SmoothShapeKeepingPieces(mesh_, settings_.shape_smooth_time, settings_.shape_smooth_iterations);
        std::string detail =
            fmt::format("{} x mean-curvature flow, time step {}", settings_.shape_smooth_iterations, settings_.shape_smooth_time);
        if (done.kept_pieces > 0) detail += fmt::format("; pieces left as they were (a step halved them): {}", done.kept_pieces);
        if (done.unfolded_places > 0) detail += fmt::format("; vertices put back where a step made faces cross: {}", done.unfolded_places);
        return detail;
      });
    }
  }

  void Decimate() {
    if (!settings_.decimate || mesh_.is_empty()) return;
    Run("decimate", [&] {
      const std::size_t faces = mesh_.number_of_faces(), edges = mesh_.number_of_edges();
      const std::size_t target_faces = settings_.decimate_faces > 0 ? std::size_t(settings_.decimate_faces)
                                                                    : std::size_t(std::llround(settings_.decimate_ratio * double(faces)));
      if (target_faces >= faces && settings_.decimate_max_error <= 0) return std::string("nothing to do");
      if (settings_.decimate_method == io::DecimateMethod::kBatch) {
        mesh_.collect_garbage();  // vertex and face indices become 0..n-1
        std::vector<Vec3d> points;
        points.reserve(mesh_.number_of_vertices());
        for (VertexIndex v : mesh_.vertices()) points.emplace_back(mesh_.point(v).x(), mesh_.point(v).y(), mesh_.point(v).z());
        std::vector<std::array<std::uint32_t, 3>> triangles;
        triangles.reserve(faces);
        for (FaceIndex f : mesh_.faces()) {
          const HalfedgeIndex h = mesh_.halfedge(f);
          triangles.push_back({std::uint32_t(mesh_.source(h)), std::uint32_t(mesh_.target(h)), std::uint32_t(mesh_.target(mesh_.next(h)))});
        }
        const DecimateResult r = DecimateQuadric(points, triangles, std::min(target_faces, faces), settings_.decimate_max_error);
        mesh_.clear();
        mesh_.reserve(Mesh::size_type(points.size()), Mesh::size_type(triangles.size() * 3 / 2), Mesh::size_type(triangles.size()));
        for (const Vec3d& p : points) mesh_.add_vertex(Point(p.x, p.y, p.z));
        std::size_t refused = 0;  // none expected: the collapses keep the mesh manifold
        for (const auto& t : triangles)
          if (mesh_.add_face(VertexIndex(t[0]), VertexIndex(t[1]), VertexIndex(t[2])) == Mesh::null_face()) ++refused;
        if (refused > 0) report_.warnings.push_back(fmt::format("decimation: {} faces could not be rebuilt (non-manifold)", refused));
        return fmt::format("{} edge collapses in {} passes: {} -> {} faces{}", r.collapses, r.passes, faces, mesh_.number_of_faces(),
                           r.reached_target ? "" : " (stopped early: error bound or no valid collapse)");
      }
      // The collapse counts edges: E = 3F/2 on a closed triangle mesh, so scale by the current ratio.
      const DecimationStop stop{std::size_t(double(edges) * double(std::min(target_faces, faces)) / double(faces)),
                                settings_.decimate_max_error * settings_.decimate_max_error};
      SMS::GarlandHeckbert_plane_policies<Mesh, Kernel> policies(mesh_);
      const int collapsed = SMS::edge_collapse(mesh_, stop, params::get_cost(policies.get_cost()).get_placement(policies.get_placement()));
      mesh_.collect_garbage();
      // CGAL 5.5 returns the edges removed: three per collapse on a closed mesh.
      return fmt::format("{} edges removed by CGAL edge_collapse: {} -> {} faces", collapsed, faces, mesh_.number_of_faces());
    });
  }

  void SelfIntersections() {
    if (settings_.self_intersections == io::SelfIntersections::kOff || mesh_.is_empty()) return;
    auto count = [&] {
      std::vector<std::pair<FaceIndex, FaceIndex>> pairs;
      // Sequential: on a 1M-face ball CGAL 5.5's parallel variant took 3.8 s CPU on 1 thread and
      // 6.0 s wall on 2 (it collects every box pair first), the sequential one 1.3 s and 2.0 s.
      // Frames run in parallel instead (-j).
      PMP::self_intersections<CGAL::Sequential_tag>(faces(mesh_), mesh_, std::back_inserter(pairs));
      return std::int64_t(pairs.size());
    };
    Run("self_intersections", [&] {
      report_.self_intersecting_pairs = count();
      return fmt::format("{} intersecting face pairs", report_.self_intersecting_pairs);
    });
    if (settings_.self_intersections == io::SelfIntersections::kRemove && report_.self_intersecting_pairs > 0) {
      Run("remove_self_intersections", [&] {
        const std::int64_t before = report_.self_intersecting_pairs;
        const bool solved = PMP::experimental::remove_self_intersections(mesh_, params::preserve_genus(false));
        mesh_.collect_garbage();
        report_.self_intersecting_pairs = count();
        report_.self_intersections_removed = report_.self_intersecting_pairs == 0;
        if (report_.self_intersecting_pairs > 0)
          report_.warnings.push_back(fmt::format("CGAL 5.5's experimental remove_self_intersections left {} of {} intersecting pairs",
                                                 report_.self_intersecting_pairs, before));
        return fmt::format("{} -> {} intersecting pairs ({})", before, report_.self_intersecting_pairs,
                           solved ? "CGAL reports success" : "CGAL could not remove all");
      });
    }
  }

  io::TriMesh Result() { return ToTriMesh(mesh_); }

 private:
  double MeanEdge() const {
    double sum = 0;
    for (auto e : mesh_.edges())
      sum += std::sqrt(CGAL::to_double(CGAL::squared_distance(mesh_.point(mesh_.vertex(e, 0)), mesh_.point(mesh_.vertex(e, 1)))));
    return mesh_.number_of_edges() ? sum / double(mesh_.number_of_edges()) : 0;
  }

  const io::CleanupSettings& settings_;
  CleanReport& report_;
  Mesh mesh_;
};

}  // namespace

CleanResult Clean(const io::TriMesh& input, const io::CleanupSettings& settings) {
  if (input.triangles.empty()) throw InputError("mesh is empty (no triangles)");
  for (std::size_t i = 0; i < input.positions.size(); ++i)
    if (!IsFinite(input.positions[i])) throw InputError(fmt::format("vertex {} has a NaN or infinite coordinate", i));
  for (std::size_t f = 0; f < input.triangles.size(); ++f)
    for (std::uint32_t v : input.triangles[f])
      if (v >= input.positions.size()) throw InputError(fmt::format("triangle {} refers to vertex {} of {}", f, v, input.positions.size()));

  const auto start = std::chrono::steady_clock::now();
  CleanResult result;
  CleanReport& report = result.report;
  report.before = ComputeStats(input);

  Chain chain(settings, report);
  chain.Load(input);
  chain.RemoveDegenerate();
  chain.RemoveSmallComponents();
  chain.FillHoles();
  chain.Remesh(report.before.mean_edge_length);
  // Decimation before smoothing: relaxation then evens out the triangles the collapses leave, and
  // runs on half as many vertices.
  chain.Decimate();
  chain.Smooth();
  chain.SelfIntersections();
  result.mesh = chain.Result();

  if (settings.transfer_velocity && !input.velocities.empty() && !result.mesh.positions.empty()) {
    const auto t0 = std::chrono::steady_clock::now();
    const double cpu0 = ProcessCpuSeconds();
    result.mesh.velocities = TransferVelocities(input, result.mesh.positions);
    report.operations.push_back({"velocity", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
                                 ProcessCpuSeconds() - cpu0, "from the nearest point of the input surface"});
    report.velocities = true;
  }

  report.after = ComputeStats(result.mesh);
  if (result.mesh.empty()) report.warnings.push_back("the cleaned mesh is empty");
  if (!report.after.manifold())
    report.warnings.push_back(fmt::format("could not be made manifold: {} non-manifold edges, {} non-manifold vertices",
                                          report.after.non_manifold_edges, report.after.non_manifold_vertices));
  if (report.after.boundary_edges > 0)
    report.warnings.push_back(
        fmt::format("not closed: {} boundary edges in {} holes left", report.after.boundary_edges, report.holes_left));
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace rime::clean
