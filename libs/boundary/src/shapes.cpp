#include "rime/boundary/shapes.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <utility>

#include "rime/core/error.h"

namespace rime::boundary {
namespace {

constexpr double kPi = std::numbers::pi;

int SegmentsFor(double length, double max_edge, int minimum = 1) {
  return std::max(minimum, static_cast<int>(std::ceil(length / max_edge - 1e-9)));
}

std::uint32_t AddVertex(io::TriMesh& mesh, double x, double y, double z) {
  mesh.positions.push_back(Vec3f(float(x), float(y), float(z)));
  return static_cast<std::uint32_t>(mesh.positions.size() - 1);
}

// A regular grid on the box face perpendicular to `axis` at `side` (+1/-1), counter-clockwise seen
// from the side its normal points to. Coordinates are computed by one per-axis formula so that
// vertices shared by two faces are bit-identical (the sampler welds them).
void AddBoxFace(io::TriMesh& mesh, const Vec3d& size, const int counts[3], int axis, int side) {
  const int a = side > 0 ? (axis + 1) % 3 : (axis + 2) % 3;  // e_a x e_b = side * e_axis
  const int b = side > 0 ? (axis + 2) % 3 : (axis + 1) % 3;
  const auto coord = [&](int ax, int i) { return -0.5 * size[ax] + size[ax] * i / counts[ax]; };
  const auto first = static_cast<std::uint32_t>(mesh.positions.size());
  for (int j = 0; j <= counts[b]; ++j)
    for (int i = 0; i <= counts[a]; ++i) {
      Vec3d p;
      p[axis] = 0.5 * side * size[axis];
      p[a] = coord(a, i);
      p[b] = coord(b, j);
      AddVertex(mesh, p.x, p.y, p.z);
    }
  const auto at = [&](int i, int j) { return first + std::uint32_t(j * (counts[a] + 1) + i); };
  for (int j = 0; j < counts[b]; ++j)
    for (int i = 0; i < counts[a]; ++i) {
      mesh.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      mesh.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
}

// Surface of revolution about z. Each profile point (rho, z) becomes a ring of vertices no more
// than max_edge apart (a single pole vertex when rho = 0); consecutive rings are stitched by
// walking both by angle. The surface faces T_theta x T_profile, i.e. outward when the profile runs
// counter-clockwise in the (rho, z) half-plane.
io::TriMesh MakeRevolution(const std::vector<std::pair<double, double>>& profile, bool closed, double max_edge) {
  io::TriMesh mesh;
  std::vector<std::uint32_t> ring_first, ring_count;
  for (const auto& [rho, z] : profile) {
    const int n = rho <= 1e-12 ? 1 : SegmentsFor(2 * kPi * rho, max_edge, 6);
    ring_first.push_back(static_cast<std::uint32_t>(mesh.positions.size()));
    ring_count.push_back(n);
    if (n == 1) {
      AddVertex(mesh, 0, 0, z);
      continue;
    }
    for (int i = 0; i < n; ++i) {
      const double angle = 2 * kPi * i / n;
      AddVertex(mesh, rho * std::cos(angle), rho * std::sin(angle), z);
    }
  }
  const std::size_t rings = profile.size();
  const std::size_t stitches = closed ? rings : rings - 1;
  for (std::size_t r = 0; r < stitches; ++r) {
    const std::size_t s = (r + 1) % rings;
    const std::uint32_t na = ring_count[r], nb = ring_count[s];
    const std::uint32_t steps_a = na == 1 ? 0 : na, steps_b = nb == 1 ? 0 : nb;
    const auto a = [&](std::uint32_t i) { return ring_first[r] + (na == 1 ? 0 : i % na); };
    const auto b = [&](std::uint32_t j) { return ring_first[s] + (nb == 1 ? 0 : j % nb); };
    std::uint32_t i = 0, j = 0;
    while (i < steps_a || j < steps_b) {
      // Advance on the ring whose next vertex comes first in angle.
      const bool advance_a = j >= steps_b || (i < steps_a && double(i + 1) / na < double(j + 1) / nb);
      if (advance_a) {
        mesh.triangles.push_back({a(i), a(i + 1), b(j)});
        ++i;
      } else {
        mesh.triangles.push_back({a(i), b(j + 1), b(j)});
        ++j;
      }
    }
  }
  return mesh;
}

void AppendSegment(std::vector<std::pair<double, double>>& profile, std::pair<double, double> to, double max_edge) {
  const auto from = profile.back();
  const int n = SegmentsFor(std::hypot(to.first - from.first, to.second - from.second), max_edge);
  for (int k = 1; k <= n; ++k) {
    const double t = double(k) / n;
    profile.emplace_back(k == n ? to.first : from.first + t * (to.first - from.first),
                         k == n ? to.second : from.second + t * (to.second - from.second));
  }
}

void RequirePositive(double value, const char* what) {
  if (!(value > 0) || !std::isfinite(value)) throw InputError(fmt::format("{} must be positive and finite, got {}", what, value));
}

}  // namespace

io::TriMesh MakeBox(const Vec3d& size, bool container, double max_edge) {
  RequirePositive(size.x, "box size x");
  RequirePositive(size.y, "box size y");
  RequirePositive(size.z, "box size z");
  const int counts[3] = {SegmentsFor(size.x, max_edge), SegmentsFor(size.y, max_edge), SegmentsFor(size.z, max_edge)};
  io::TriMesh mesh;
  for (int axis = 0; axis < 3; ++axis)
    for (int side : {-1, 1}) {
      if (container && axis == 2 && side > 0) continue;  // open top
      AddBoxFace(mesh, size, counts, axis, side);
    }
  if (container)  // walls face the fluid inside
    for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
  return mesh;
}

io::TriMesh MakePlane(double size_x, double size_y, double max_edge) {
  RequirePositive(size_x, "plane size x");
  RequirePositive(size_y, "plane size y");
  const Vec3d size(size_x, size_y, 0);
  const int counts[3] = {SegmentsFor(size_x, max_edge), SegmentsFor(size_y, max_edge), 1};
  io::TriMesh mesh;
  AddBoxFace(mesh, size, counts, 2, 1);
  return mesh;
}

io::TriMesh MakeSphere(double radius, double max_edge) {
  RequirePositive(radius, "sphere radius");
  const int n = SegmentsFor(kPi * radius, max_edge, 4);
  std::vector<std::pair<double, double>> profile;
  for (int k = 0; k <= n; ++k) {
    const double phi = -0.5 * kPi + kPi * k / n;
    const bool pole = k == 0 || k == n;
    profile.emplace_back(pole ? 0.0 : radius * std::cos(phi), pole ? (k == 0 ? -radius : radius) : radius * std::sin(phi));
  }
  return MakeRevolution(profile, false, max_edge);
}

io::TriMesh MakeCylinder(double radius, double height, double max_edge) {
  RequirePositive(radius, "cylinder radius");
  RequirePositive(height, "cylinder height");
  std::vector<std::pair<double, double>> profile{{0.0, -0.5 * height}};
  AppendSegment(profile, {radius, -0.5 * height}, max_edge);  // bottom cap
  AppendSegment(profile, {radius, 0.5 * height}, max_edge);   // side
  AppendSegment(profile, {0.0, 0.5 * height}, max_edge);      // top cap
  return MakeRevolution(profile, false, max_edge);
}

io::TriMesh MakeTorus(double major_radius, double minor_radius, double max_edge) {
  RequirePositive(major_radius, "torus radius");
  RequirePositive(minor_radius, "torus minor_radius");
  if (minor_radius >= major_radius) throw InputError("torus minor_radius must be below radius");
  const int n = SegmentsFor(2 * kPi * minor_radius, max_edge, 8);
  std::vector<std::pair<double, double>> profile;
  for (int k = 0; k < n; ++k) {
    const double phi = 2 * kPi * k / n;
    profile.emplace_back(major_radius + minor_radius * std::cos(phi), minor_radius * std::sin(phi));
  }
  return MakeRevolution(profile, true, max_edge);
}

io::TriMesh MakeProceduralMesh(const io::SolidObject& o, double max_edge) {
  RequirePositive(max_edge, "tessellation edge length");
  switch (o.shape) {
    case io::SolidShape::kBox:
      return MakeBox(o.size, o.container, max_edge);
    case io::SolidShape::kPlane:
      return MakePlane(o.size.x, o.size.y, max_edge);
    case io::SolidShape::kSphere:
      return MakeSphere(o.radius, max_edge);
    case io::SolidShape::kCylinder:
      return MakeCylinder(o.radius, o.height, max_edge);
    case io::SolidShape::kTorus:
      return MakeTorus(o.radius, o.minor_radius, max_edge);
    case io::SolidShape::kMesh:
      break;
  }
  throw InputError(fmt::format("'{}' is not a procedural shape (box, plane, sphere, cylinder, torus)", io::EnumName(o.shape)));
}

double ProceduralSurfaceArea(const io::SolidObject& o) {
  double area = 0;
  const Vec3d& s = o.size;
  switch (o.shape) {
    case io::SolidShape::kBox:
      area = 2 * (s.x * s.y + s.y * s.z + s.z * s.x) - (o.container ? s.x * s.y : 0);
      break;
    case io::SolidShape::kPlane:
      area = s.x * s.y;
      break;
    case io::SolidShape::kSphere:
      area = 4 * kPi * o.radius * o.radius;
      break;
    case io::SolidShape::kCylinder:
      area = 2 * kPi * o.radius * (o.height + o.radius);
      break;
    case io::SolidShape::kTorus:
      area = 4 * kPi * kPi * o.radius * o.minor_radius;
      break;
    case io::SolidShape::kMesh:
      break;
  }
  const Vec3d& k = o.transform.scale;
  const double stretch = std::max({std::abs(k.x), std::abs(k.y), std::abs(k.z)});
  return area * stretch * stretch;
}

Vec3d AffineTransform::Apply(const Vec3d& x) const { return linear * x + offset; }
double AffineTransform::Determinant() const { return rime::Determinant(linear); }
double AffineTransform::MaxStretch() const {
  // Frobenius norm bounds the spectral norm; exact for rotations times uniform scale / sqrt(3).
  double best = 0;
  for (int j = 0; j < 3; ++j) best = std::max(best, Norm(linear.Column(j)));
  return best;
}

AffineTransform MakeTransform(const io::Transform& t) {
  Mat3<double> scale = Mat3<double>::Identity();
  for (int a = 0; a < 3; ++a) scale.m[a][a] = t.scale[a];
  // y-up -> z-up: a quarter turn about +x.
  const Mat3<double> up = t.up_axis == io::UpAxis::kY ? RotationXYZDegrees(Vec3d(90, 0, 0)) : Mat3<double>::Identity();
  AffineTransform result;
  result.linear = RotationXYZDegrees(t.rotate_deg) * scale * up;
  result.offset = t.translate;
  return result;
}

void ApplyTransform(io::TriMesh& mesh, const io::Transform& transform) {
  const AffineTransform m = MakeTransform(transform);
  for (auto& p : mesh.positions) p = Vec3f(m.Apply(Vec3d(p)));
  if (m.Determinant() < 0)
    for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
  mesh.normals.clear();
}

std::string DescribeTransform(const io::Transform& t) {
  return fmt::format("up {}, scale ({:g}, {:g}, {:g}), rotate ({:g}, {:g}, {:g}) deg X then Y then Z, translate ({:g}, {:g}, {:g}) m",
                     io::EnumName(t.up_axis), t.scale.x, t.scale.y, t.scale.z, t.rotate_deg.x, t.rotate_deg.y, t.rotate_deg.z,
                     t.translate.x, t.translate.y, t.translate.z);
}

}  // namespace rime::boundary
