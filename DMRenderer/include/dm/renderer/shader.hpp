// dm/renderer/shader.hpp — GLSL programs with compile and link errors that
// say which program, which stage and which source line failed.
//
// Sources are GLSL 4.50 core without the #version line (added here, with
// optional #define lines, so one source serves several variants). A compile
// error quotes the driver's log and the offending source line; a link error
// names the program. Uniform locations are looked up once and cached.
//
// @code
//   auto prog = dm::ShaderProgram::create("flat", {{dm::ShaderStage::Vertex, vs}, {dm::ShaderStage::Fragment,
//   fs}}); if (!prog) return prog.error();              // "shader flat, fragment: 0:7(2): error: ..."
//   prog->use(); prog->set("u_color", dm::Vec4f(1, 0, 0, 1));
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstdint>
#include <initializer_list>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace dm {

enum class ShaderStage : unsigned char { Vertex, Geometry, Fragment, Compute };

/// "vertex", "geometry", "fragment", "compute".
const char* toString(ShaderStage s) noexcept;

/// One stage's GLSL source (no #version line).
struct ShaderSource {
  ShaderStage stage;
  std::string_view source;
};

using Mat4f = Eigen::Matrix4f;
using Mat3f = Eigen::Matrix3f;

/// A linked GLSL program. Move-only; deleted with its context current.
class ShaderProgram {
 public:
  /// Compiles and links; `defines` become "#define NAME VALUE" lines after
  /// "#version 450 core". Fails with the stage, driver log and source line.
  static Result<ShaderProgram> create(std::string_view name, std::initializer_list<ShaderSource> stages,
                                      const std::vector<std::pair<std::string, std::string>>& defines = {});

  ShaderProgram() = default;
  ShaderProgram(ShaderProgram&& o) noexcept;
  ShaderProgram& operator=(ShaderProgram&& o) noexcept;
  ShaderProgram(const ShaderProgram&) = delete;
  ShaderProgram& operator=(const ShaderProgram&) = delete;
  ~ShaderProgram();

  const std::string& name() const { return name_; }
  std::uint32_t id() const { return id_; }
  bool valid() const { return id_ != 0; }

  /// Makes this the current program.
  void use() const;
  /// Location of a uniform, -1 when the program has none by that name
  /// (unused uniforms are optimised away; setting -1 is a no-op in GL).
  int location(std::string_view uniform);

  void set(std::string_view uniform, int v);
  void set(std::string_view uniform, float v);
  void set(std::string_view uniform, const Vec2f& v);
  void set(std::string_view uniform, const Vec3f& v);
  void set(std::string_view uniform, const Vec4f& v);
  void set(std::string_view uniform, const Mat3f& m);
  void set(std::string_view uniform, const Mat4f& m);

 private:
  std::string name_;
  std::uint32_t id_ = 0;
  std::vector<std::pair<std::string, int>> locations_;
};

}  // namespace dm
