// lwsccd's Python extension (_lwsccd): the pipelines behind AnyPipeline (policies by name), the
// mesh loaders and the built-in simulation, with NumPy arrays in and out. The public Python API
// (python/lwsccd/__init__.py) validates arrays and builds the structured results on top of this;
// the GPU backend is in gpu_backend.cu, compiled in when LWSCCD_PYTHON_WITH_GPU is defined.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/pair.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <atomic>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "gpu_backend.hpp"
#include "lwsccd/core/parallel.hpp"
#include "lwsccd/io/dataset.hpp"
#include "lwsccd/io/mesh_io.hpp"
#include "lwsccd/io/render.hpp"
#include "lwsccd/pipeline/any_pipeline.hpp"
#include "lwsccd/simulation/simulation.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace {

using HostPositions = nb::ndarray<const double, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;
using HostPositionsF = nb::ndarray<const float, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;
using HostFaces = nb::ndarray<const std::int64_t, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;

// A NumPy array that owns a copy of `values` (shape given; the product must equal values.size()).
template <class T>
nb::ndarray<nb::numpy, T> numpy_array(std::vector<T>&& values, std::initializer_list<size_t> shape) {
  auto* owned = new std::vector<T>(std::move(values));
  nb::capsule owner(owned, [](void* p) noexcept { delete static_cast<std::vector<T>*>(p); });
  return nb::ndarray<nb::numpy, T>(owned->data(), shape, owner);
}

// The points of an (n, 3) array, as they are (double or float: the pipeline widens float exactly).
template <class S>
std::vector<lwsccd::Vec3<S>> to_points(const nb::ndarray<const S, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>& a) {
  std::vector<lwsccd::Vec3<S>> points(a.shape(0));
  if (!points.empty()) std::memcpy(points.data(), a.data(), points.size() * sizeof(lwsccd::Vec3<S>));
  return points;
}

nb::ndarray<nb::numpy, double> points_array(const std::vector<lwsccd::Vec3d>& points) {
  std::vector<double> flat(points.size() * 3);
  if (!points.empty()) std::memcpy(flat.data(), points.data(), flat.size() * sizeof(double));
  return numpy_array(std::move(flat), {points.size(), 3});
}

nb::ndarray<nb::numpy, std::int64_t> faces_array(const lwsccd::TriangleMesh& mesh) {
  std::vector<std::int64_t> flat;
  flat.reserve(mesh.faces().size() * 3);
  for (const lwsccd::Face& f : mesh.faces())
    for (int k = 0; k < 3; ++k) flat.push_back(f.v[k]);
  return numpy_array(std::move(flat), {mesh.faces().size(), 3});
}

nb::dict counts_dict(const lwsccd::NarrowPhaseCounts& c) {
  nb::dict d;
  d["pairs"] = c.pairs;
  d["certified_hits"] = c.certified_hits;
  d["certified_misses"] = c.certified_misses;
  d["fallbacks"] = c.fallbacks;
  d["screened"] = c.screened;
  d["single_misses"] = c.single_misses;
  d["single_descents"] = c.single_descents;
  d["float_pair_leaves"] = c.float_pair_leaves;
  return d;
}

nb::dict stats_dict(const lwsccd::StepStats& s) {
  nb::dict d;
  d["refit_ms"] = s.refit_ms;
  d["traverse_ms"] = s.traverse_ms;
  d["features_ms"] = s.features_ms;
  d["narrow_ms"] = s.narrow_ms;
  d["total_ms"] = s.total_ms;
  d["bvtt_nodes"] = s.bvtt_nodes;
  d["front_size"] = s.front_size;
  d["triangle_pairs"] = s.triangle_pairs;
  d["feature_pairs_vf"] = s.feature_pairs_vf;
  d["feature_pairs_ee"] = s.feature_pairs_ee;
  d["hits_vf"] = s.hits_vf;
  d["hits_ee"] = s.hits_ee;
  d["gave_up"] = s.gave_up;
  d["narrow_survivors"] = s.narrow_survivors;
  d["narrow_warp_searches"] = s.narrow_warp_searches;
  d["narrow_vf"] = counts_dict(s.narrow_vf);
  d["narrow_ee"] = counts_dict(s.narrow_ee);
  d["peak_device_bytes"] = s.peak_device_bytes;
  nb::dict memory;
  lwsccd::for_each_part(s.device_memory, [&](const char* name, std::size_t bytes) { memory[name] = bytes; });
  d["device_memory"] = memory;
  d["reruns"] = s.reruns;
  d["device_allocations"] = s.device_allocations;
  d["traversal_relaunches"] = s.traversal_relaunches;
  d["traversal_parts"] = s.traversal_parts;
  d["narrow_parts"] = s.narrow_parts;
  d["rebuilt"] = s.rebuilt;
  d["restarted_from_root"] = s.restarted_from_root;
  return d;
}

// One contact as Python sees it: VERTEX_FACE_DTYPE / EDGE_EDGE_DTYPE of the package (two int64
// element indices, a float64 TOI, 24 bytes); the records are handed over as bytes and viewed with
// that dtype, so building the structured arrays costs no further pass.
struct ContactRecord {
  std::int64_t first, second;
  double toi;
};
static_assert(sizeof(ContactRecord) == 24, "the package's structured dtypes have 24-byte records");

// A step's contacts for Python: vertex-face pairs as (vertex, face), edge-edge pairs as (edge,
// edge), each with its TOI (feature ids of the library turned into element indices).
nb::dict outcome_dict(const lwsccd::TriangleMesh& mesh, const lwsccd::StepOutcome& outcome) {
  const std::int64_t v = mesh.num_vertices(), e = mesh.num_edges();
  auto records = [](const std::vector<lwsccd::FeatureHit<double>>& hits, std::int64_t first_base, std::int64_t second_base) {
    std::vector<std::uint8_t> bytes(hits.size() * sizeof(ContactRecord));
    auto* out = reinterpret_cast<ContactRecord*>(bytes.data());
    for (std::size_t i = 0; i < hits.size(); ++i)
      out[i] = {static_cast<std::int64_t>(hits[i].first) - first_base, static_cast<std::int64_t>(hits[i].second) - second_base,
                hits[i].toi};
    const std::size_t n = bytes.size();
    return numpy_array(std::move(bytes), {n});
  };
  nb::dict d;
  d["vf"] = records(outcome.contacts.vf, 0, v + e);
  d["ee"] = records(outcome.contacts.ee, v, v);
  d["earliest_toi"] = outcome.contacts.earliest_toi;
  d["gave_up"] = outcome.contacts.gave_up;
  d["stats"] = stats_dict(outcome.stats);
  return d;
}

// A device array owned by Python (freed by free_device_array when the last reference goes).
template <class T>
nb::ndarray<T> device_array(T* data, std::initializer_list<size_t> shape) {
  nb::capsule owner(data, [](void* p) noexcept { lwsccd_python::free_device_array(p); });
  int device = 0;
  return nb::ndarray<T>(data, shape, owner, {}, nb::dtype<T>(), nb::device::cuda::value, device);
}

// A step's device contacts as new device arrays (DLPack-capable): vf_pairs / ee_pairs (n x 2
// int64 element indices) and vf_toi / ee_toi (float64).
nb::dict device_contacts(const lwsccd::TriangleMesh& mesh, const lwsccd::AnyDeviceContacts& c) {
  const std::int64_t v = mesh.num_vertices(), e = mesh.num_edges();
  nb::dict d;
  auto put = [&](const void* hits, std::size_t n, std::int64_t first_base, std::int64_t second_base, const char* pairs_key,
                 const char* toi_key) {
    const lwsccd_python::DeviceHitArrays a = lwsccd_python::copy_device_hits(hits, n, c.toi_is_double, first_base, second_base);
    d[pairs_key] = device_array(a.pairs, {n, 2});
    d[toi_key] = device_array(a.toi, {n});
  };
  put(c.vf, c.num_vf, 0, v + e, "vf_pairs", "vf_toi");
  put(c.ee, c.num_ee, v, v, "ee_pairs", "ee_toi");
  return d;
}

lwsccd::CcdMode parse_mode(const std::string& mode) {
  if (mode == "contacts") return lwsccd::CcdMode::contacts;
  if (mode == "earliest") return lwsccd::CcdMode::earliest;
  if (mode == "set") return lwsccd::CcdMode::set;
  throw lwsccd::InputError("lwsccd.Pipeline", "mode", "unknown '" + mode + "' (accepted: contacts, earliest, set)");
}

// The extension's pipeline: an AnyPipeline of either backend and the mesh it was made for.
class Pipeline {
 public:
  Pipeline(std::int64_t num_vertices, const HostFaces& faces, std::vector<std::int64_t> face_body,
           std::vector<bool> body_self_collides, const std::string& bv, const std::string& scheduler,
           const std::string& method, const std::string& precision, const std::string& mode, double min_separation,
           double tolerance, int max_iterations, bool front_tracking, double rebuild_factor, double front_growth_limit,
           std::size_t device_memory_budget, std::size_t part_pairs, std::int64_t threads, std::int64_t fp64_ratio,
           const std::string& device, const std::vector<std::int64_t>& devices) {
    if (num_vertices < 1 || num_vertices > 0x7fffffff)
      throw lwsccd::InputError("lwsccd.Pipeline", "num_vertices", "must be in [1, 2^31), got " + std::to_string(num_vertices));
    std::vector<lwsccd::Face> mesh_faces(faces.shape(0));
    const std::int64_t* f = faces.data();
    for (std::size_t i = 0; i < mesh_faces.size(); ++i)
      for (int k = 0; k < 3; ++k) {
        const std::int64_t index = f[3 * i + k];
        if (index < 0 || index >= num_vertices)
          throw lwsccd::InputError("lwsccd.Pipeline", "face " + std::to_string(i),
                                   "vertex index " + std::to_string(index) + " outside [0, " + std::to_string(num_vertices) + ")");
        mesh_faces[i].v[k] = static_cast<lwsccd::index_t>(index);
      }
    mesh_ = std::make_shared<const lwsccd::TriangleMesh>(static_cast<lwsccd::index_t>(num_vertices), std::move(mesh_faces),
                                                         "lwsccd.Pipeline faces");
    lwsccd::BodyLayout layout;
    if (!face_body.empty()) {
      if (face_body.size() != mesh_->faces().size())
        throw lwsccd::InputError("lwsccd.Pipeline", "bodies", std::to_string(face_body.size()) + " entries for " +
                                 std::to_string(mesh_->faces().size()) + " faces");
      for (std::size_t i = 0; i < face_body.size(); ++i) {
        if (face_body[i] < 0 || face_body[i] > 0x7fffffff)
          throw lwsccd::InputError("lwsccd.Pipeline", "bodies[" + std::to_string(i) + "]",
                                   std::to_string(face_body[i]) + " is not a body id (0 or more)");
        layout.face_body.push_back(static_cast<lwsccd::index_t>(face_body[i]));
      }
      layout.body_self_collides = std::move(body_self_collides);
    }
    lwsccd::PipelineParams params;
    params.mode = parse_mode(mode);
    params.min_separation = min_separation;
    params.tolerance = tolerance;
    params.max_iterations = max_iterations;
    params.front_tracking = front_tracking;
    params.rebuild_factor = rebuild_factor;
    params.front_growth_limit = front_growth_limit;
    params.device_memory_budget = device_memory_budget;
    params.part_pairs = part_pairs;
    if (threads < 0 || threads > (1 << 16))
      throw lwsccd::InputError("lwsccd.Pipeline", "threads", "must be in [0, 65536] (0: every core), got " + std::to_string(threads));
    params.threads = static_cast<unsigned>(threads);
    if (fp64_ratio < 0 || fp64_ratio > (1 << 16))
      throw lwsccd::InputError("lwsccd.Pipeline", "fp64_ratio", "must be in [0, 65536] (0: the device's own), got " +
                               std::to_string(fp64_ratio));
    params.fp64_ratio = static_cast<int>(fp64_ratio);
    const lwsccd::PolicyChoice choice{bv, scheduler, method, precision};
    lwsccd::validate(choice);
    if (!devices.empty()) {  // a step split over these CUDA devices (one: a pipeline on that device)
      if (device != "gpu")
        throw lwsccd::InputError("lwsccd.Pipeline", "devices", "names CUDA devices: it needs device='gpu' or 'auto', got '" + device + "'");
      std::vector<int> ordinals;
      for (const std::int64_t d : devices) {
        if (d < 0 || d > 0x7fffffff)
          throw lwsccd::InputError("lwsccd.Pipeline", "devices", std::to_string(d) + " is not a CUDA device ordinal");
        ordinals.push_back(static_cast<int>(d));
      }
      pipeline_ = lwsccd_python::make_multi_gpu_pipeline(mesh_, layout, params, choice, std::move(ordinals));
    } else if (device == "gpu") pipeline_ = lwsccd_python::make_gpu_pipeline(mesh_, layout, params, choice);
    else if (device == "cpu") pipeline_ = lwsccd::cpu::make_any_pipeline(mesh_, layout, params, choice);
    else throw lwsccd::InputError("lwsccd.Pipeline", "device", "unknown '" + device + "' (accepted: auto, gpu, cpu)");
  }

  // Host positions in float64 or float32 (step_f32: uploaded as float, widened exactly).
  template <class S>
  nb::dict step(const nb::ndarray<const S, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>& x0,
                const nb::ndarray<const S, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>& x1) {
    check_count(x0.shape(0), "x0");
    check_count(x1.shape(0), "x1");
    // Read in place (the arrays are C-contiguous (n, 3)); the outcome's lists are kept between
    // steps, so the GPU backend downloads into warm memory.
    const lwsccd::Span<const lwsccd::Vec3<S>> p0(reinterpret_cast<const lwsccd::Vec3<S>*>(x0.data()), x0.shape(0));
    const lwsccd::Span<const lwsccd::Vec3<S>> p1(reinterpret_cast<const lwsccd::Vec3<S>*>(x1.data()), x1.shape(0));
    {
      nb::gil_scoped_release unlocked;
      pipeline_->step_into(p0, p1, kept_);
    }
    return outcome_dict(*mesh_, kept_);
  }

  // Positions in device memory, by address (the Python side took them from
  // __cuda_array_interface__ or DLPack and checked shape, dtype and layout); `float32` says
  // their type.
  nb::dict step_from_device(std::uintptr_t x0, std::uintptr_t x1, bool float32) {
    lwsccd::StepOutcome outcome;
    {
      nb::gil_scoped_release unlocked;
      outcome = float32 ? pipeline_->step_from_device(reinterpret_cast<const lwsccd::Vec3f*>(x0), reinterpret_cast<const lwsccd::Vec3f*>(x1))
                        : pipeline_->step_from_device(reinterpret_cast<const lwsccd::Vec3d*>(x0), reinterpret_cast<const lwsccd::Vec3d*>(x1));
    }
    return outcome_dict(*mesh_, std::move(outcome));
  }

  // As step_from_device, with the contacts copied into new device arrays (DLPack-capable).
  nb::dict step_on_device(std::uintptr_t x0, std::uintptr_t x1, bool float32) {
    lwsccd::AnyDeviceContacts contacts;
    {
      nb::gil_scoped_release unlocked;
      contacts = float32 ? pipeline_->step_on_device(reinterpret_cast<const lwsccd::Vec3f*>(x0), reinterpret_cast<const lwsccd::Vec3f*>(x1))
                         : pipeline_->step_on_device(reinterpret_cast<const lwsccd::Vec3d*>(x0), reinterpret_cast<const lwsccd::Vec3d*>(x1));
    }
    nb::dict d = device_contacts(*mesh_, contacts);
    d["earliest_toi"] = contacts.earliest_toi;
    d["gave_up"] = contacts.gave_up;
    d["stats"] = stats_dict(contacts.stats);
    return d;
  }

  // The picture of a step (lwsccd::cpu::render_contacts): the contacts come back as the records
  // step() made (bytes), turned into the library's feature ids again.
  void render(const std::string& path, const HostPositions& x0, const HostPositions& x1,
              const nb::ndarray<const std::uint8_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>& vf,
              const nb::ndarray<const std::uint8_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>& ee, double earliest_toi,
              int width, int height) {
    check_count(x0.shape(0), "x0");
    check_count(x1.shape(0), "x1");
    const std::int64_t v = mesh_->num_vertices(), e = mesh_->num_edges();
    lwsccd::NarrowPhaseResult<double> contacts;
    auto hits = [&](const auto& bytes, std::int64_t first_base, std::int64_t second_base, std::vector<lwsccd::FeatureHit<double>>& out,
                    std::int64_t first_limit, std::int64_t second_limit, const char* name) {
      if (bytes.shape(0) % sizeof(ContactRecord) != 0)
        throw lwsccd::InputError("lwsccd.Pipeline.render", name, "is not an array of contact records");
      const auto* r = reinterpret_cast<const ContactRecord*>(bytes.data());
      for (std::size_t i = 0; i < bytes.shape(0) / sizeof(ContactRecord); ++i) {
        if (r[i].first < 0 || r[i].first >= first_limit || r[i].second < 0 || r[i].second >= second_limit)
          throw lwsccd::InputError("lwsccd.Pipeline.render", name, "contact " + std::to_string(i) + " is not of this mesh");
        out.push_back({static_cast<lwsccd::index_t>(r[i].first + first_base), static_cast<lwsccd::index_t>(r[i].second + second_base),
                       r[i].toi});
      }
    };
    hits(vf, 0, v + e, contacts.vf, v, mesh_->num_faces(), "vertex_face");
    hits(ee, v, v, contacts.ee, e, e, "edge_edge");
    contacts.earliest_toi = earliest_toi;
    const std::vector<lwsccd::Vec3d> p0 = to_points(x0), p1 = to_points(x1);
    nb::gil_scoped_release unlocked;
    lwsccd::cpu::render_contacts(path, *mesh_, p0, p1, contacts, width, height);
  }

  void restart_from_root() { pipeline_->restart_from_root(); }
  const lwsccd::TriangleMesh& mesh() const { return *mesh_; }

  // (edges given that are no edge of a face, vertices in no face): what lwsccd.ipc refuses
  // (codimensional elements, which ipc-toolkit checks and lwsccd does not). Each edge is looked up
  // in the mesh's own, on all cores.
  std::pair<std::size_t, std::size_t> count_loose(const nb::ndarray<const std::int64_t, nb::shape<-1, 2>, nb::c_contig, nb::device::cpu>& edges) const {
    const std::int64_t* e = edges.data();
    const std::int64_t nv = mesh_->num_vertices();
    std::atomic<std::size_t> loose_edges{0}, loose_vertices{0};
    nb::gil_scoped_release unlocked;
    lwsccd::detail::parallel_ranges(edges.shape(0), lwsccd::detail::grain_for(edges.shape(0)), [&](std::size_t begin, std::size_t end) {
      std::size_t loose = 0;
      for (std::size_t i = begin; i < end; ++i) {
        const std::int64_t a = e[2 * i], b = e[2 * i + 1];
        const bool in_range = a >= 0 && b >= 0 && a < nv && b < nv;
        loose += !in_range || mesh_->find_edge(static_cast<lwsccd::index_t>(a), static_cast<lwsccd::index_t>(b)) < 0;
      }
      loose_edges += loose;
    });
    lwsccd::detail::parallel_ranges(static_cast<std::size_t>(nv), lwsccd::detail::grain_for(static_cast<std::size_t>(nv)),
                                    [&](std::size_t begin, std::size_t end) {
                                      std::size_t loose = 0;
                                      for (std::size_t v = begin; v < end; ++v)
                                        loose += mesh_->vertex_faces(static_cast<lwsccd::index_t>(v)).size() == 0;
                                      loose_vertices += loose;
                                    });
    return {loose_edges.load(), loose_vertices.load()};
  }
  std::string backend() const { return pipeline_->backend(); }

 private:
  void check_count(std::size_t n, const char* name) const {
    if (n != static_cast<std::size_t>(mesh_->num_vertices()))
      throw lwsccd::InputError("lwsccd.Pipeline.step", name, std::to_string(n) + " points for a mesh of " +
                                                                   std::to_string(mesh_->num_vertices()) + " vertices");
  }

  std::shared_ptr<const lwsccd::TriangleMesh> mesh_;
  std::unique_ptr<lwsccd::AnyPipeline> pipeline_;
  lwsccd::StepOutcome kept_;  ///< the last host step's outcome (its lists' memory reused)
};

nb::dict frame_dict(const lwsccd::Frame& frame) {
  nb::dict d;
  d["vertices"] = points_array(frame.positions);
  std::vector<std::int64_t> faces;
  for (const lwsccd::Face& f : frame.faces)
    for (int k = 0; k < 3; ++k) faces.push_back(f.v[k]);
  d["faces"] = numpy_array(std::move(faces), {frame.faces.size(), 3});
  std::vector<std::int64_t> source(frame.face_source.begin(), frame.face_source.end());
  d["face_source"] = numpy_array(std::move(source), {frame.face_source.size()});
  d["source"] = frame.source;
  return d;
}

nb::dict step_dict(const lwsccd::Step& step) {
  nb::dict d;
  d["faces"] = faces_array(*step.mesh);
  d["x0"] = points_array(step.x0);
  d["x1"] = points_array(step.x1);
  return d;
}

}  // namespace

NB_MODULE(_lwsccd, m) {
  m.doc() = "lwsccd's compiled core; use the lwsccd package's API instead.";
  nb::register_exception_translator([](const std::exception_ptr& p, void*) {
    try {
      std::rethrow_exception(p);
    } catch (const lwsccd::InputError& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    } catch (const lwsccd::Error& e) {
      PyErr_SetString(PyExc_RuntimeError, e.what());
    }
  });

  nb::class_<Pipeline>(m, "Pipeline")
      .def(nb::init<std::int64_t, const HostFaces&, std::vector<std::int64_t>, std::vector<bool>, const std::string&,
                    const std::string&, const std::string&, const std::string&, const std::string&, double, double, int, bool,
                    double, double, std::size_t, std::size_t, std::int64_t, std::int64_t, const std::string&,
                    const std::vector<std::int64_t>&>(),
           "num_vertices"_a, "faces"_a, "face_body"_a, "body_self_collides"_a, "bv"_a, "scheduler"_a, "method"_a,
           "precision"_a, "mode"_a, "min_separation"_a, "tolerance"_a, "max_iterations"_a, "front_tracking"_a,
           "rebuild_factor"_a, "front_growth_limit"_a, "device_memory_budget"_a, "part_pairs"_a, "threads"_a, "fp64_ratio"_a,
           "device"_a, "devices"_a)
      .def("step", &Pipeline::step<double>, "x0"_a, "x1"_a)
      .def("step_f32", &Pipeline::step<float>, "x0"_a, "x1"_a)
      .def("step_from_device", &Pipeline::step_from_device, "x0"_a, "x1"_a, "float32"_a)
      .def("step_on_device", &Pipeline::step_on_device, "x0"_a, "x1"_a, "float32"_a)
      .def("restart_from_root", &Pipeline::restart_from_root)
      .def("count_loose", &Pipeline::count_loose, "edges"_a)
      .def("render", &Pipeline::render, "path"_a, "x0"_a, "x1"_a, "vf"_a, "ee"_a, "earliest_toi"_a, "width"_a, "height"_a)
      .def_prop_ro("backend", &Pipeline::backend)
      .def_prop_ro("num_vertices", [](const Pipeline& p) { return p.mesh().num_vertices(); })
      .def_prop_ro("faces", [](const Pipeline& p) { return faces_array(p.mesh()); }, nb::rv_policy::move)
      .def_prop_ro("edges", [](const Pipeline& p) {
        std::vector<std::int64_t> flat;
        for (const lwsccd::Edge& e : p.mesh().edges()) flat.push_back(e.v[0]), flat.push_back(e.v[1]);
        return numpy_array(std::move(flat), {p.mesh().edges().size(), 2});
      }, nb::rv_policy::move);

  m.def("gpu_name", &lwsccd_python::gpu_name);
  m.def("release_cached_memory", &lwsccd_python::release_cached_memory);
  m.def("synchronize_stream", &lwsccd_python::synchronize_stream, "stream"_a);
  // The device address of a DLPack CUDA array of (n, 3) float64 or float32, C-contiguous
  // (nanobind checks; float64 tried first).
  m.def("dlpack_address", [](nb::ndarray<const double, nb::shape<-1, 3>, nb::c_contig, nb::device::cuda> a) {
    return reinterpret_cast<std::uintptr_t>(a.data());
  }, "array"_a);
  m.def("dlpack_address", [](nb::ndarray<const float, nb::shape<-1, 3>, nb::c_contig, nb::device::cuda> a) {
    return reinterpret_cast<std::uintptr_t>(a.data());
  }, "array"_a);
  m.def("built_with_gpu", [] { return lwsccd_python::kBuiltWithGpu; });
  m.def("built_with_nccl", [] { return lwsccd_python::kBuiltWithNccl; });
  m.def("gpu_count", &lwsccd_python::gpu_count);
  m.def("load_frame", [](const std::string& path) { return frame_dict(lwsccd::load_frame(path)); }, "path"_a);
  m.def("load_step", [](const std::string& t0, const std::string& t1) { return step_dict(lwsccd::load_step(t0, t1)); },
        "path_t0"_a, "path_t1"_a);
  m.def("load_scene", [](const std::string& folder) {
    const lwsccd::Scene scene = lwsccd::load_scene(folder);
    nb::dict d = step_dict(scene.step);
    d["name"] = scene.name;
    return d;
  }, "folder"_a);
  m.def("load_sequence", [](const std::string& folder) {
    const lwsccd::Sequence sequence = lwsccd::load_sequence(folder);
    nb::dict d;
    d["faces"] = faces_array(*sequence.mesh());
    nb::list frames;
    for (std::size_t i = 0; i < sequence.num_frames(); ++i) frames.append(points_array(sequence.frame(i)));
    d["frames"] = frames;
    return d;
  }, "folder"_a);

  nb::class_<lwsccd::ClothBallSimulation>(m, "ClothBallSimulation")
      .def(nb::init<std::size_t>(), "target_triangles"_a)
      .def("next_step", [](lwsccd::ClothBallSimulation& s) { return step_dict(s.next_step()); })
      .def("advance", &lwsccd::ClothBallSimulation::advance, "frames"_a)
      .def_prop_ro("faces", [](const lwsccd::ClothBallSimulation& s) { return faces_array(*s.mesh()); }, nb::rv_policy::move)
      .def_prop_ro("face_body", [](const lwsccd::ClothBallSimulation& s) {
        std::vector<std::int64_t> body(s.layout().face_body.begin(), s.layout().face_body.end());
        const std::size_t n = body.size();
        return numpy_array(std::move(body), {n});
      }, nb::rv_policy::move)
      .def_prop_ro("body_self_collides", [](const lwsccd::ClothBallSimulation& s) { return s.layout().body_self_collides; });
}
