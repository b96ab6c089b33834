#include "planner/geometry/mesh.hpp"

#include <cctype>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <unordered_map>

#include <fstream>
#include <chrono>
#include <cerrno>

#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <assimp/DefaultLogger.hpp>
#include <assimp/Importer.hpp>
#include <assimp/LogStream.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include "common/errors.hpp"
#include "common/worker_process.hpp"

namespace scancell::planner {
namespace {

struct Vec3Hash {
  std::size_t operator()(const Eigen::Vector3d& v) const noexcept {
    std::size_t h = 1469598103934665603ull;
    for (int i = 0; i < 3; ++i) {
      double d = v[i] == 0.0 ? 0.0 : v[i];  // fold -0 into +0
      std::uint64_t bits;
      static_assert(sizeof bits == sizeof d);
      std::memcpy(&bits, &d, sizeof d);
      h = (h ^ bits) * 1099511628211ull;
    }
    return h;
  }
};

/// Collects what assimp logs as errors while it reads. Some of its readers log a malformed element and carry
/// on (the OFF reader keeps a face whose index is out of range); we refuse such a file instead.
class ErrorCollector : public Assimp::LogStream {
 public:
  void write(const char* message) override {
    std::string m(message);
    while (!m.empty() && (m.back() == '\n' || m.back() == '\r')) m.pop_back();
    if (first.empty()) first = m;
  }
  std::string first;
};

/// Assimp's text parsers read "nan" as 0 without a word. A text mesh file must not hold a token that parses
/// as a non-finite number (nan, inf, 1e999); binary files (any NUL or control byte) are checked after
/// import instead.
void refuse_non_finite_tokens(const std::string& name) {
  std::ifstream in(name, std::ios::binary);
  std::string text((std::istreambuf_iterator<char>(in)), {});
  for (unsigned char c : text)
    if (c == 0 || (c < 9) || (c > 13 && c < 32)) return;  // binary
  std::size_t line = 1, pos = 0;
  while (pos < text.size()) {
    const char c = text[pos];
    if (c == '\n') {
      ++line;
      ++pos;
      continue;
    }
    if (std::isspace(static_cast<unsigned char>(c))) {
      ++pos;
      continue;
    }
    if (c == '#') {  // OBJ/OFF comment to end of line
      while (pos < text.size() && text[pos] != '\n') ++pos;
      continue;
    }
    std::size_t end = pos;
    while (end < text.size() && !std::isspace(static_cast<unsigned char>(text[end]))) ++end;
    const std::string token = text.substr(pos, end - pos);
    char* stop = nullptr;
    const double v = std::strtod(token.c_str(), &stop);
    if (stop && *stop == '\0' && stop != token.c_str() && !std::isfinite(v))
      throw MeshError(name + ": line " + std::to_string(line) + ": non-finite coordinate '" + token + "'");
    pos = end;
  }
}

}  // namespace

namespace {

/// The import itself (assimp), no locking: the caller owns assimp's process-global logger.
TriangleMesh import_mesh(const std::string& name, MeshLoadReport* report) {
  Assimp::DefaultLogger::create("", Assimp::Logger::NORMAL, 0);
  ErrorCollector* errors = new ErrorCollector;  // owned by the logger once attached
  Assimp::DefaultLogger::get()->attachStream(errors, Assimp::Logger::Err);
  struct KillLogger {
    ~KillLogger() { Assimp::DefaultLogger::kill(); }
  } kill_logger;
  Assimp::Importer importer;
  // No aiProcess_FindDegenerates / FindInvalidData: we report what was wrong ourselves rather than let the
  // importer repair silently. PreTransformVertices bakes node transforms so multi-node files stay correct.
  const aiScene* scene = importer.ReadFile(
      name, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices | aiProcess_PreTransformVertices |
                aiProcess_ValidateDataStructure | aiProcess_SortByPType);
  if (!scene) throw MeshError(name + ": cannot parse mesh: " + importer.GetErrorString());
  if (!errors->first.empty()) throw MeshError(name + ": malformed: " + errors->first);
  if (scene->mNumMeshes == 0) throw MeshError(name + ": file holds no mesh");

  TriangleMesh mesh;
  MeshLoadReport local;
  // Weld across assimp meshes (STL solids, OBJ groups) so the surface stays connected.
  std::unordered_map<Eigen::Vector3d, std::uint32_t, Vec3Hash> index_of;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* am = scene->mMeshes[m];
    local.file_vertices += am->mNumVertices;
    std::vector<std::uint32_t> remap(am->mNumVertices);
    for (unsigned v = 0; v < am->mNumVertices; ++v) {
      const aiVector3D& a = am->mVertices[v];
      const Eigen::Vector3d p(a.x, a.y, a.z);
      if (!p.allFinite()) {
        std::ostringstream os;
        os << name << ": mesh " << m << " vertex " << v << " has a non-finite coordinate (" << a.x << ", "
           << a.y << ", " << a.z << ")";
        throw MeshError(os.str());
      }
      auto [it, inserted] = index_of.emplace(p, static_cast<std::uint32_t>(mesh.vertices.size()));
      if (inserted) mesh.vertices.push_back(p);
      remap[v] = it->second;
    }
    for (unsigned f = 0; f < am->mNumFaces; ++f) {
      const aiFace& face = am->mFaces[f];
      ++local.file_faces;
      if (face.mNumIndices != 3) continue;  // points and lines (sorted out by SortByPType) are not surface
      Triangle t;
      for (int k = 0; k < 3; ++k) {
        const unsigned idx = face.mIndices[k];
        if (idx >= am->mNumVertices) {
          std::ostringstream os;
          os << name << ": mesh " << m << " face " << f << " index " << idx << " is out of range (" << am->mNumVertices
             << " vertices)";
          throw MeshError(os.str());
        }
        t[k] = remap[idx];
      }
      mesh.triangles.push_back(t);
    }
  }
  validate_mesh(mesh, name, &local);
  if (report) *report = local;
  return mesh;
}

template <class T>
void put(std::string& out, const T& v) {
  out.append(reinterpret_cast<const char*>(&v), sizeof v);
}
template <class T>
T get(const std::string& in, std::size_t& at) {
  if (at + sizeof(T) > in.size()) throw MeshError("mesh reader: truncated reply");
  T v;
  std::memcpy(&v, in.data() + at, sizeof v);
  at += sizeof v;
  return v;
}

/// Child side: the import's outcome as bytes (status 0 + report + mesh, or status 1 + the message).
std::string import_to_bytes(const std::string& name) {
  std::string out;
  try {
    MeshLoadReport rep;
    const TriangleMesh m = import_mesh(name, &rep);
    put<std::uint8_t>(out, 0);
    for (std::size_t v : {rep.file_vertices, rep.file_faces, rep.degenerate_dropped, rep.unreferenced_vertices,
                          m.vertices.size(), m.triangles.size()})
      put<std::uint64_t>(out, v);
    for (const auto& v : m.vertices) out.append(reinterpret_cast<const char*>(v.data()), 3 * sizeof(double));
    for (const auto& t : m.triangles) out.append(reinterpret_cast<const char*>(t.data()), 3 * sizeof(std::uint32_t));
  } catch (const std::exception& e) {
    out.clear();
    put<std::uint8_t>(out, 1);
    out += e.what();
  }
  return out;
}

constexpr const char* kReaderKind = "mesh-reader";

/// The worker's side: the import's outcome, whole, on `out_fd`.
int reader_main(int out_fd, const std::string& name) {
  const std::string out = import_to_bytes(name);
  std::size_t done = 0;
  while (done < out.size()) {
    const ssize_t n = ::write(out_fd, out.data() + done, out.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return 3;
    done += static_cast<std::size_t>(n);
  }
  return 0;
}

// In a mesh-reader worker this reads the file and ends the process before main() (common/worker_process.hpp).
[[maybe_unused]] const bool reader_started = run_if_worker(kReaderKind, &reader_main);

}  // namespace

TriangleMesh load_mesh(const std::filesystem::path& path, MeshLoadReport* report, std::chrono::milliseconds time_limit,
                       const std::atomic<int>* cancel) {
  const std::string name = path.string();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw MeshError(name + ": no such mesh file");
  if (std::filesystem::file_size(path, ec) == 0)
    throw MeshError(name + ": file is empty");

  refuse_non_finite_tokens(name);

  // Untrusted files are parsed in a worker process with a time limit: assimp's PLY reader loops for ever on a
  // misspelt end_header (tests/data/bad/ply-header-typo-hang.ply), and a crash in a parser must not take
  // the daemon with it. The worker is this executable started afresh, not a fork: a fork of this
  // multithreaded process could inherit a lock another thread held (common/worker_process.hpp).
  SpawnedWorker worker;
  try {
    worker = spawn_worker(kReaderKind, name);
  } catch (const std::exception& e) {
    throw MeshError(name + ": " + e.what());
  }
  const pid_t pid = worker.pid;
  const int rd = worker.read_fd;
  std::string bytes;
  const auto deadline = std::chrono::steady_clock::now() + time_limit;
  bool timed_out = false, cancelled = false;
  char buf[65536];
  while (true) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) {
      timed_out = true;
      break;
    }
    if (cancel && cancel->load() != 0) {
      cancelled = true;
      break;
    }
    pollfd p{rd, POLLIN, 0};
    const int r = ::poll(&p, 1, static_cast<int>(std::min<long long>(left.count(), cancel ? 50 : 1000)));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) continue;
    const ssize_t n = ::read(rd, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    bytes.append(buf, static_cast<std::size_t>(n));
  }
  ::close(rd);
  if (timed_out || cancelled) ::kill(pid, SIGKILL);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (cancelled) throw MeshError(name + ": reading stopped by request (the daemon is stopping)");
  if (timed_out)
    throw MeshError(name + ": the mesh reader did not finish within " + std::to_string(time_limit.count() / 1000.0).substr(0, 5) +
                    " s and was stopped; the file is malformed (a PLY header without 'end_header'?) or too large");
  if (WIFSIGNALED(status))
    throw MeshError(name + ": the mesh reader crashed (signal " + std::to_string(WTERMSIG(status)) + "); the file is malformed");
  if (bytes.empty()) throw MeshError(name + ": the mesh reader ended without an answer (exit " + std::to_string(WEXITSTATUS(status)) + ")");
  std::size_t at = 0;
  if (get<std::uint8_t>(bytes, at) != 0) throw MeshError(bytes.substr(1));
  MeshLoadReport local;
  local.file_vertices = get<std::uint64_t>(bytes, at);
  local.file_faces = get<std::uint64_t>(bytes, at);
  local.degenerate_dropped = get<std::uint64_t>(bytes, at);
  local.unreferenced_vertices = get<std::uint64_t>(bytes, at);
  const std::uint64_t nv = get<std::uint64_t>(bytes, at), nt = get<std::uint64_t>(bytes, at);
  if (nv > bytes.size() / 24 || nt > bytes.size() / 12 || at + nv * 24 + nt * 12 != bytes.size())
    throw MeshError(name + ": the mesh reader's reply is inconsistent");
  TriangleMesh mesh;
  mesh.vertices.resize(nv);
  mesh.triangles.resize(nt);
  for (auto& v : mesh.vertices) {
    std::memcpy(v.data(), bytes.data() + at, 24);
    at += 24;
  }
  for (auto& t : mesh.triangles) {
    std::memcpy(t.data(), bytes.data() + at, 12);
    at += 12;
  }
  if (report) *report = local;
  return mesh;
}

void validate_mesh(TriangleMesh& mesh, const std::string& name, MeshLoadReport* report) {
  MeshLoadReport local;
  MeshLoadReport& r = report ? *report : local;
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
    if (!mesh.vertices[v].allFinite()) {
      std::ostringstream os;
      os << name << ": vertex " << v << " has a non-finite coordinate";
      throw MeshError(os.str());
    }
  }
  std::vector<Triangle> kept;
  kept.reserve(mesh.triangles.size());
  std::vector<char> used(mesh.vertices.size(), 0);
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    const Triangle& t = mesh.triangles[f];
    for (int k = 0; k < 3; ++k) {
      if (t[k] >= mesh.vertices.size()) {
        std::ostringstream os;
        os << name << ": face " << f << " index " << t[k] << " is out of range (" << mesh.vertices.size()
           << " vertices)";
        throw MeshError(os.str());
      }
    }
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || !(triangle_area(mesh, t) > 0.0)) {
      ++r.degenerate_dropped;
      continue;
    }
    kept.push_back(t);
    for (auto i : t) used[i] = 1;
  }
  if (kept.empty()) {
    std::ostringstream os;
    os << name << ": no usable triangles (" << mesh.triangles.size() << " faces, " << r.degenerate_dropped
       << " degenerate)";
    throw MeshError(os.str());
  }
  mesh.triangles = std::move(kept);
  // Compact away vertices no triangle uses: they are not surface and would become rows nothing can cover.
  std::vector<std::uint32_t> remap(mesh.vertices.size(), UINT32_MAX);
  std::vector<Eigen::Vector3d> verts;
  verts.reserve(mesh.vertices.size());
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
    if (!used[v]) {
      ++r.unreferenced_vertices;
      continue;
    }
    remap[v] = static_cast<std::uint32_t>(verts.size());
    verts.push_back(mesh.vertices[v]);
  }
  for (auto& t : mesh.triangles)
    for (auto& i : t) i = remap[i];
  mesh.vertices = std::move(verts);
}

Eigen::Vector3d bounding_extent(const TriangleMesh& mesh) {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  for (const auto& v : mesh.vertices) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  return mesh.vertices.empty() ? Eigen::Vector3d::Zero() : Eigen::Vector3d(hi - lo);
}

double fit_scale(const TriangleMesh& mesh, double longest_side_mm) {
  const double longest = bounding_extent(mesh).maxCoeff();
  if (!(longest > 0.0)) throw MeshError("mesh has zero extent; cannot fit it to a size");
  return longest_side_mm / longest;
}

void apply_scale(TriangleMesh& mesh, double scale) {
  for (auto& v : mesh.vertices) v *= scale;
}

double triangle_area(const TriangleMesh& mesh, const Triangle& t) {
  const Eigen::Vector3d& a = mesh.vertices[t[0]];
  return 0.5 * (mesh.vertices[t[1]] - a).cross(mesh.vertices[t[2]] - a).norm();
}

}  // namespace scancell::planner

namespace scancell::planner {

namespace {

/// Calls `f(edge, uses)` once per undirected edge of the mesh with the number of triangles using it.
template <class F>
void for_each_edge(const TriangleMesh& mesh, F&& f) {
  std::vector<std::pair<std::uint32_t, std::uint32_t>> e;
  e.reserve(mesh.triangles.size() * 3);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) e.push_back(std::minmax(t[k], t[(k + 1) % 3]));
  std::sort(e.begin(), e.end());
  for (std::size_t i = 0; i < e.size();) {
    std::size_t j = i;
    while (j < e.size() && e[j] == e[i]) ++j;
    f(e[i], j - i);
    i = j;
  }
}

}  // namespace

EdgeCounts count_edges(const TriangleMesh& mesh) {
  EdgeCounts c;
  for_each_edge(mesh, [&](const auto&, std::size_t uses) {
    ++c.edges;
    c.open += uses == 1;
    c.non_manifold += uses > 2;
  });
  return c;
}

std::vector<std::uint8_t> open_edge_vertices(const TriangleMesh& mesh) {
  std::vector<std::uint8_t> out(mesh.vertices.size(), 0);
  for_each_edge(mesh, [&](const auto& edge, std::size_t uses) {
    if (uses == 1) out[edge.first] = out[edge.second] = 1;
  });
  return out;
}

void append_mesh(TriangleMesh& into, const TriangleMesh& more) {
  const auto base = static_cast<std::uint32_t>(into.vertices.size());
  into.vertices.insert(into.vertices.end(), more.vertices.begin(), more.vertices.end());
  for (const auto& t : more.triangles) into.triangles.push_back({base + t[0], base + t[1], base + t[2]});
}

TriangleMesh refine_edges(const TriangleMesh& mesh, double max_edge_mm) {
  if (!(max_edge_mm > 0.0)) throw std::invalid_argument("refine_edges: max_edge_mm must be > 0");
  TriangleMesh m = mesh;
  const double limit2 = max_edge_mm * max_edge_mm;
  for (int pass = 0; pass < 64; ++pass) {
    std::unordered_map<std::uint64_t, std::uint32_t> mid;
    auto key = [](std::uint32_t a, std::uint32_t b) {
      return a < b ? (std::uint64_t{a} << 32 | b) : (std::uint64_t{b} << 32 | a);
    };
    // Mark: one midpoint per long edge, shared by both triangles, so the split stays conforming.
    for (const auto& t : m.triangles)
      for (int k = 0; k < 3; ++k) {
        const std::uint32_t a = t[k], b = t[(k + 1) % 3];
        if ((m.vertices[a] - m.vertices[b]).squaredNorm() <= limit2) continue;
        if (mid.emplace(key(a, b), 0).second) {
          mid[key(a, b)] = static_cast<std::uint32_t>(m.vertices.size());
          const Eigen::Vector3d midpoint = 0.5 * (m.vertices[a] + m.vertices[b]);  // evaluate before push_back
          m.vertices.push_back(midpoint);
        }
      }
    if (mid.empty()) return m;
    std::vector<Triangle> next;
    next.reserve(m.triangles.size() * 2);
    for (const auto& t : m.triangles) {
      std::array<std::int64_t, 3> e;  // midpoint of edge (t[k], t[k+1]) or -1
      int marked = 0;
      for (int k = 0; k < 3; ++k) {
        const auto it = mid.find(key(t[k], t[(k + 1) % 3]));
        e[k] = it == mid.end() ? std::int64_t{-1} : std::int64_t{it->second};
        marked += e[k] >= 0;
      }
      auto M = [&](int k) { return static_cast<std::uint32_t>(e[k]); };
      if (marked == 0) {
        next.push_back(t);
      } else if (marked == 3) {
        next.push_back({t[0], M(0), M(2)});
        next.push_back({M(0), t[1], M(1)});
        next.push_back({M(2), M(1), t[2]});
        next.push_back({M(0), M(1), M(2)});
      } else if (marked == 1) {
        const int k = e[0] >= 0 ? 0 : e[1] >= 0 ? 1 : 2;  // split edge (t[k], t[k+1]) against t[k+2]
        const std::uint32_t a = t[k], b = t[(k + 1) % 3], c = t[(k + 2) % 3];
        next.push_back({a, M(k), c});
        next.push_back({M(k), b, c});
      } else {
        const int k = e[0] < 0 ? 0 : e[1] < 0 ? 1 : 2;  // the unsplit edge (t[k], t[k+1])
        const std::uint32_t a = t[k], b = t[(k + 1) % 3], c = t[(k + 2) % 3];
        const std::uint32_t mbc = M((k + 1) % 3), mca = M((k + 2) % 3);
        next.push_back({mbc, c, mca});  // the corner at c
        // The quad a, b, mbc, mca: cut along its shorter diagonal.
        if ((m.vertices[a] - m.vertices[mbc]).squaredNorm() <= (m.vertices[b] - m.vertices[mca]).squaredNorm()) {
          next.push_back({a, b, mbc});
          next.push_back({a, mbc, mca});
        } else {
          next.push_back({a, b, mca});
          next.push_back({b, mbc, mca});
        }
      }
    }
    m.triangles = std::move(next);
  }
  throw std::runtime_error("refine_edges: did not converge in 64 passes");
}

}  // namespace scancell::planner
