// python_script.hpp — scene scripts in Python (dm/engine/script.hpp): the
// loader of ".py" scripts, shared by the dmplatform package (its import
// registers it, so dmplatform.run(scene) runs them in the caller's
// interpreter) and the dmplatform program (which starts an embedded one on
// the first script). docs/python.md, "Scripted scenes".
#pragma once

namespace dm::python {

/// Registers ".py" with dm::registerScriptLanguage for this process.
void registerPythonScripts();

}  // namespace dm::python
