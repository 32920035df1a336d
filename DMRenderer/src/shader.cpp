// shader.cpp — GLSL compile/link with located errors, uniform cache.
#include <dm/renderer/shader.hpp>

#include <cstdlib>
#include <string>

#include "gl.hpp"

namespace dm {

namespace {

GLenum glStage(ShaderStage s) {
  switch (s) {
    case ShaderStage::Vertex:
      return GL_VERTEX_SHADER;
    case ShaderStage::Geometry:
      return GL_GEOMETRY_SHADER;
    case ShaderStage::Fragment:
      return GL_FRAGMENT_SHADER;
    case ShaderStage::Compute:
      return GL_COMPUTE_SHADER;
  }
  return GL_VERTEX_SHADER;
}

std::string nthLine(const std::string& text, long n) {
  long line = 1;
  std::size_t pos = 0;
  while (line < n && pos < text.size()) {
    pos = text.find('\n', pos);
    if (pos == std::string::npos) return {};
    ++pos;
    ++line;
  }
  const std::size_t end = text.find('\n', pos);
  return text.substr(pos, end == std::string::npos ? std::string::npos : end - pos);
}

// Mesa writes "0:LINE(COL): error: ...", NVIDIA "0(LINE) : error ...".
long firstErrorLine(const std::string& log) {
  const std::size_t p = log.find("0:");
  if (p != std::string::npos) return std::strtol(log.c_str() + p + 2, nullptr, 10);
  const std::size_t q = log.find("0(");
  if (q != std::string::npos) return std::strtol(log.c_str() + q + 2, nullptr, 10);
  return 0;
}

}  // namespace

const char* toString(ShaderStage s) noexcept {
  switch (s) {
    case ShaderStage::Vertex:
      return "vertex";
    case ShaderStage::Geometry:
      return "geometry";
    case ShaderStage::Fragment:
      return "fragment";
    case ShaderStage::Compute:
      return "compute";
  }
  return "?";
}

Result<ShaderProgram> ShaderProgram::create(std::string_view name, std::initializer_list<ShaderSource> stages,
                                            const std::vector<std::pair<std::string, std::string>>& defines) {
  if (stages.size() == 0)
    return fail(ErrorCode::InvalidArgument, "no shader stages", "shader " + std::string(name));
  std::string header = "#version 450 core\n";
  for (const auto& [k, v] : defines) header += "#define " + k + " " + v + "\n";
  ShaderProgram prog;
  prog.name_ = name;
  prog.id_ = glCreateProgram();
  if (prog.id_ == 0)
    return fail(ErrorCode::InvalidArgument, "glCreateProgram failed (is a GL context current?)",
                "shader " + std::string(name));
  std::vector<GLuint> shaders;
  auto cleanup = [&] {
    for (GLuint s : shaders) glDeleteShader(s);
  };
  for (const ShaderSource& st : stages) {
    const std::string full = header + "#line 1\n" + std::string(st.source);
    GLuint sh = glCreateShader(glStage(st.stage));
    shaders.push_back(sh);
    const char* src = full.c_str();
    glShaderSource(sh, 1, &src, nullptr);
    glCompileShader(sh);
    GLint okFlag = 0;
    glGetShaderiv(sh, GL_COMPILE_STATUS, &okFlag);
    if (!okFlag) {
      GLint len = 0;
      glGetShaderiv(sh, GL_INFO_LOG_LENGTH, &len);
      std::string log(static_cast<std::size_t>(std::max(len, 1)), '\0');
      glGetShaderInfoLog(sh, len, nullptr, log.data());
      while (!log.empty() && (log.back() == '\0' || log.back() == '\n')) log.pop_back();
      const long line = firstErrorLine(log);
      std::string hint;
      if (line > 0) hint = formatString("line %ld: %s", line, nthLine(std::string(st.source), line).c_str());
      cleanup();
      return fail(ErrorCode::Parse, log, "shader " + std::string(name) + ", " + toString(st.stage) + " stage",
                  hint);
    }
    glAttachShader(prog.id_, sh);
  }
  glLinkProgram(prog.id_);
  GLint linked = 0;
  glGetProgramiv(prog.id_, GL_LINK_STATUS, &linked);
  cleanup();
  if (!linked) {
    GLint len = 0;
    glGetProgramiv(prog.id_, GL_INFO_LOG_LENGTH, &len);
    std::string log(static_cast<std::size_t>(std::max(len, 1)), '\0');
    glGetProgramInfoLog(prog.id_, len, nullptr, log.data());
    while (!log.empty() && (log.back() == '\0' || log.back() == '\n')) log.pop_back();
    return fail(ErrorCode::Parse, "link failed: " + log, "shader " + std::string(name),
                "check that stage outputs and inputs match in name and type");
  }
  return prog;
}

ShaderProgram::ShaderProgram(ShaderProgram&& o) noexcept { *this = std::move(o); }

ShaderProgram& ShaderProgram::operator=(ShaderProgram&& o) noexcept {
  if (this != &o) {
    if (id_ != 0) glDeleteProgram(id_);
    name_ = std::move(o.name_);
    id_ = std::exchange(o.id_, 0u);
    locations_ = std::move(o.locations_);
  }
  return *this;
}

ShaderProgram::~ShaderProgram() {
  if (id_ != 0) glDeleteProgram(id_);
}

void ShaderProgram::use() const { glUseProgram(id_); }

int ShaderProgram::location(std::string_view uniform) {
  for (const auto& [n, loc] : locations_)
    if (n == uniform) return loc;
  const std::string key(uniform);
  const int loc = glGetUniformLocation(id_, key.c_str());
  locations_.emplace_back(key, loc);
  return loc;
}

void ShaderProgram::set(std::string_view u, int v) { glProgramUniform1i(id_, location(u), v); }
void ShaderProgram::set(std::string_view u, float v) { glProgramUniform1f(id_, location(u), v); }
void ShaderProgram::set(std::string_view u, const Vec2f& v) {
  glProgramUniform2fv(id_, location(u), 1, v.data());
}
void ShaderProgram::set(std::string_view u, const Vec3f& v) {
  glProgramUniform3fv(id_, location(u), 1, v.data());
}
void ShaderProgram::set(std::string_view u, const Vec4f& v) {
  glProgramUniform4fv(id_, location(u), 1, v.data());
}
void ShaderProgram::set(std::string_view u, const Mat3f& m) {
  glProgramUniformMatrix3fv(id_, location(u), 1, GL_FALSE, m.data());
}
void ShaderProgram::set(std::string_view u, const Mat4f& m) {
  glProgramUniformMatrix4fv(id_, location(u), 1, GL_FALSE, m.data());
}

}  // namespace dm
