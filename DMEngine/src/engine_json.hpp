// engine_json.hpp (private) — the JSON the engines' summaries share.
#pragma once

#include <dm/core/types.hpp>

#include <nlohmann/json.hpp>

namespace dm::engine_json {

/// [x, y, z].
inline nlohmann::json vec3(const Vec3& v) { return nlohmann::json::array({v.x(), v.y(), v.z()}); }

}  // namespace dm::engine_json
