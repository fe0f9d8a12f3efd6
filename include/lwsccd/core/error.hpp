// lwsccd — host-side error types.
#pragma once

#include <stdexcept>
#include <string>

namespace lwsccd {

/// Base of every exception the library throws. `what()` says what went wrong and where.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

/// Malformed or invalid input: a file, a mesh, positions, parameters.
/// `what()` names the source (file or argument), the element (line, face, vertex) and the problem.
class InputError : public Error {
 public:
  InputError(const std::string& source, const std::string& where, const std::string& problem)
      : Error(source + (where.empty() ? std::string() : ": " + where) + ": " + problem),
        source_(source),
        where_(where),
        problem_(problem) {}

  const std::string& source() const noexcept { return source_; }
  const std::string& where() const noexcept { return where_; }
  const std::string& problem() const noexcept { return problem_; }

 private:
  std::string source_;
  std::string where_;
  std::string problem_;
};

/// A failed CUDA runtime call; the message names the call, the file and the line.
class CudaError : public Error {
 public:
  explicit CudaError(const std::string& message) : Error(message) {}
};

}  // namespace lwsccd
