// dm/collide/collider_plugin.hpp — colliders added by plugins at run time.
//
// A plugin registers factories of kind "collider" (C vtable in
// dm/collide/collider_abi.h). After dm::PluginLinker has loaded it,
// registerPluginColliders() puts every such collider into a ColliderTable:
// shape-type names are resolved to ids (a name that is not a built-in kind
// is registered as a user kind with registerShapeType(), so the application
// can make shapes of it), and a host-side adapter translates shapes, poses and
// contacts between dm types and the C views. The adapter does not allocate:
// contacts go through a fixed stack buffer of DM_COLLIDER_MAX_CONTACTS.
//
// At most kMaxPluginColliders plugin colliders exist per process (adapters
// are fixed functions, one per slot). A factory already registered (same
// vtable) keeps its slot, so calling this again after a rescan is harmless.
//
// @code
//   dm::FactoryRegistry registry;
//   dm::PluginLinker linker(registry, {.searchPaths = {"/opt/dm/plugins"}});
//   linker.scan();
//   auto added = dm::registerPluginColliders(registry);   // before the world steps
//   if (!added) dm::log::warn("%s", added.error().message().c_str());
// @endcode
#pragma once

#include <dm/collide/collider_abi.h>
#include <dm/collide/query.hpp>
#include <dm/core/plugin.hpp>
#include <dm/core/result.hpp>

namespace dm {

/// Number of plugin collider slots per process.
inline constexpr int kMaxPluginColliders = 32;

/// Registers every "collider" factory of `registry` (kind ABI
/// DM_COLLIDER_KIND_ABI_VERSION) in `table`; returns how many pairs were
/// registered by this call. Fails, registering none of the bad factory's pair
/// and stopping there, with Version on another kind ABI, InvalidArgument on
/// a null function or empty type name (naming the factory and provider), and
/// Busy when the slots are used up. Must not run concurrently with queries on
/// `table`. O(factories).
Result<int> registerPluginColliders(const FactoryRegistry& registry,
                                    ColliderTable& table = ColliderTable::global());

/// The C view of `shape` (type name, parameters, mesh arrays), as a plugin
/// collider receives it. No allocation; pointers refer into `shape`.
DmShapeView shapeView(const Shape& shape) noexcept;

}  // namespace dm
