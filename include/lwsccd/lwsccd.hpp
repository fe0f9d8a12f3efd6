// lwsccd — everything that compiles with a plain C++17 compiler (CPU backend, I/O, oracle).
#pragma once

#include "lwsccd/aabb.hpp"
#include "lwsccd/bv_traits.hpp"
#include "lwsccd/config.hpp"
#include "lwsccd/dataset.hpp"
#include "lwsccd/error.hpp"
#include "lwsccd/io.hpp"
#include "lwsccd/mesh.hpp"
#include "lwsccd/morton.hpp"
#include "lwsccd/obb.hpp"
#include "lwsccd/oracle.hpp"
#include "lwsccd/scenes.hpp"
#include "lwsccd/vec.hpp"
