// dm/io/resources.hpp — plugs the DMIO readers into the resource manager and
// tells mesh files from volume files.
//
// registerIoLoaders() registers a dm::Mesh loader for every extension Assimp
// reads (readMesh(), all parts merged) and a dm::Volume loader for every
// extension readVolume() reads, so that scenes, editors and tools load
// patient and tool models through one cache:
//
// @code
//   dm::ResourceManager rm;
//   if (auto s = dm::registerIoLoaders(rm); !s) return s.error();
//   auto head = rm.load<dm::Volume>(*dm::FileSystem::global().resolve("mricron:ch2.nii.gz"));
// @endcode
//
// Import options understood by the loaders (any other key is refused, so a
// typo does not silently create a second instance of the asset):
//   dm::Mesh:   "unit" (MeshImportOptions::unit: m, cm, mm, um, inch, ft),
//               "scale" (positive factor), "weld_tolerance" (m, >= 0)
//   dm::Volume: "volume" (0-based index of the 3-D volume in a 4-D file)
#pragma once

#include <dm/core/resource.hpp>
#include <dm/core/result.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace dm {

/// The extensions readVolume() understands, lower case with the leading dot
/// (".nii", ".nii.gz", ...), parsed from supportedVolumeExtensions(). O(1).
std::vector<std::string> volumeExtensions();

/// The extensions Assimp reads, lower case with the leading dot (".obj",
/// ".stl", ...), parsed from supportedMeshExtensions().
std::vector<std::string> meshExtensions();

/// True if `path` names a volume: an existing directory (a DICOM series) or
/// a file whose name ends (case-insensitively) with one of
/// volumeExtensions(). Multi-part extensions (".nii.gz") are matched whole.
/// Does not open the file.
/// @code
///   if (dm::isVolumePath(p)) v = dm::readVolume(p); else m = dm::readMesh(p);
/// @endcode
bool isVolumePath(const std::filesystem::path& path);

/// Registers loaders for dm::Mesh (meshExtensions(), through readMesh() with
/// the parts merged) and dm::Volume (volumeExtensions(), through
/// readVolume()) with `manager`; see the header comment for the import
/// options. Fails (InvalidArgument, from ResourceManager::registerLoader)
/// when `manager` already has a Mesh or Volume loader for one of them.
/// @code
///   dm::ResourceManager rm;
///   if (auto s = dm::registerIoLoaders(rm); !s) std::cerr << s.error() << '\n';
///   auto tool = rm.load<dm::Mesh>("scalpel.stl", {{"unit", "mm"}});
/// @endcode
Status registerIoLoaders(ResourceManager& manager);

}  // namespace dm
