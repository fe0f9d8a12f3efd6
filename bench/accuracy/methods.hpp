// lwsccd-accuracy — the methods table and the measurement: every query through a method, timed,
// counted against the truth (false negatives, false positives, TOIs).
#pragma once

#include "common.hpp"
#include "inputs.hpp"

namespace {

template <class T>
struct Typed {
  std::vector<VertexFaceQuery<T>> vf;
  std::vector<EdgeEdgeQuery<T>> ee;
};

template <class T>
Typed<T> typed_queries(const Input& in) {
  Typed<T> out;
  out.vf.reserve(in.vf.size());
  out.ee.reserve(in.ee.size());
  for (const auto& p : in.vf) out.vf.push_back(lwsccd::vertex_face_query<T>(p));
  for (const auto& p : in.ee) out.ee.push_back(lwsccd::edge_edge_query<T>(p));
  return out;
}

struct Measure {
  std::vector<double> us;  // time per query, microseconds
  std::size_t queries = 0, vf_queries = 0, ee_queries = 0, truth_true = 0, truth_false = 0, unknown = 0;
  std::size_t hits = 0, fn = 0, fp = 0, gave_up = 0;
  double earliest_toi = std::numeric_limits<double>::infinity();
};

// Keeps the compiler from moving the query's work across the clock reads.
template <class V>
inline void keep(V& v) {
#if defined(__GNUC__) || defined(__clang__)
  asm volatile("" : : "g"(&v) : "memory");
#else
  (void)v;
#endif
}

template <class M, class T>
CcdResult<T> call(const VertexFaceQuery<T>& q, const CcdParams<T>& p) {
  return M::vertex_face(q, p);
}
template <class M, class T>
CcdResult<T> call(const EdgeEdgeQuery<T>& q, const CcdParams<T>& p) {
  return M::edge_edge(q, p);
}

template <class M, class T, class Q>
void run_queries(const std::vector<Q>& qs, const std::vector<signed char>& truth, const CcdParams<T>& p, Measure& m) {
  using clock = std::chrono::steady_clock;
  for (std::size_t i = 0; i < qs.size(); ++i) {
    const auto t0 = clock::now();
    CcdResult<T> r = call<M>(qs[i], p);
    keep(r);
    const auto t1 = clock::now();
    m.us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
    m.hits += r.hit;
    m.gave_up += r.gave_up;
    if (r.hit) m.earliest_toi = std::min(m.earliest_toi, static_cast<double>(r.toi));
    if (truth[i] < 0) ++m.unknown;
    else if (truth[i] == 1) {
      ++m.truth_true;
      m.fn += !r.hit;
    } else {
      ++m.truth_false;
      m.fp += r.hit;
    }
  }
}

template <class M, class T>
Measure measure(const Typed<T>& tq, const Input& in, const CcdParams<T>& p) {
  Measure m;
  m.vf_queries = tq.vf.size();
  m.ee_queries = tq.ee.size();
  m.queries = m.vf_queries + m.ee_queries;
  m.us.reserve(m.queries);
  // Warm the method (code and data caches) once, untimed.
  if (!tq.vf.empty()) {
    CcdResult<T> r = call<M>(tq.vf[0], p);
    keep(r);
  } else {
    CcdResult<T> r = call<M>(tq.ee[0], p);
    keep(r);
  }
  run_queries<M>(tq.vf, in.vf_truth, p, m);
  run_queries<M>(tq.ee, in.ee_truth, p, m);
  return m;
}

struct MethodEntry {
  const char* name;
  bool conservative;
  bool reports_toi;
  Measure (*run_float)(const Typed<float>&, const Input&, const CcdParams<float>&);
  Measure (*run_double)(const Typed<double>&, const Input&, const CcdParams<double>&);
};

template <class M>
MethodEntry entry(const char* name, bool reports_toi) {
  return {name, M::conservative, reports_toi, &measure<M, float>, &measure<M, double>};
}

const MethodEntry& method_entry(const std::string& name) {
  static const MethodEntry entries[] = {
      entry<lwsccd::CertifiedCcd>("certified", true),
      entry<lwsccd::CubicCcd>("cubic", true),
      entry<lwsccd::InclusionCcd>("inclusion", true),
      entry<lwsccd::Filtered<lwsccd::InclusionCcd>>("filtered-inclusion", true),
      entry<FilterOnly>("filter-only", false),
  };
  for (const auto& e : entries)
    if (name == e.name) return e;
  throw InputError("command line", "--methods", "unknown method '" + name + "'");
}

}  // namespace
