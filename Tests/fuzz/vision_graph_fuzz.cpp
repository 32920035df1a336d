// libFuzzer target: filter graph descriptions (JSON). Any input must give a
// validated graph or an error that says what and where (never a crash, hang
// or huge allocation). Graphs are only validated, not run.
#include <dm/vision/filter_graph.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  auto graph = dm::FilterGraph::parse(text, "<fuzz>");
  if (!graph) {
    if (graph.error().what.empty() || graph.error().where.empty()) std::abort();
    return 0;
  }
  if (graph->order().empty()) std::abort();  // a valid graph has nodes in topological order
  return 0;
}
