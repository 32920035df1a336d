// dmtool — the command line for the SDK's resources: inspect meshes and
// volumes, convert between formats, extract isosurfaces, voxelize and
// simplify meshes, replay device paths (probe), check scene files (validate)
// and render them headless (render), write CT-like phantoms (phantom), serve
// a haptic device over the network (teleop-device) (see --help).
// Exit codes: 0 success, 1 the operation failed (message on stderr),
// 2 bad command line (usage on stderr).
#include <exception>
#include <iostream>
#include <vector>

#include "common.hpp"

int main(int argc, char** argv) {
  CLI::App app{"dmtool — inspect, convert and process patient and tool models (meshes and volumes)",
               "dmtool"};
  app.require_subcommand(1);
  app.fallthrough(false);
  std::vector<dmtool::Command> commands = {
      dmtool::addInfoCommand(app),       dmtool::addDevicesCommand(app),    dmtool::addConvertCommand(app),
      dmtool::addIsosurfaceCommand(app), dmtool::addSimplifyCommand(app),   dmtool::addCollideCommand(app),
      dmtool::addVoxelizeCommand(app),   dmtool::addSpheretreeCommand(app), dmtool::addProbeCommand(app),
      dmtool::addValidateCommand(app),   dmtool::addPhantomCommand(app),
  };
#ifdef DM_HAVE_RENDERER
  commands.push_back(dmtool::addRenderCommand(app));
#endif
#ifdef DM_HAVE_NETWORK
  commands.push_back(dmtool::addTeleopDeviceCommand(app));
#endif
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help exits 0 (printed on stdout); every real usage error exits 2.
    const int code = app.exit(e);
    return code == 0 ? dmtool::kExitOk : dmtool::kExitUsage;
  }
  try {
    for (const dmtool::Command& c : commands)
      if (c.app->parsed()) return c.run();
  } catch (const std::exception& e) {
    // The SDK returns errors instead of throwing; this catches std::bad_alloc
    // and library exceptions so the tool still fails with a message.
    std::cerr << "dmtool: error: " << e.what() << '\n';
    return dmtool::kExitFailure;
  }
  return dmtool::kExitUsage;
}
