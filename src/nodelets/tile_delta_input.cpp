#include "tile_delta_input.hpp"

#include <ros/console.h>
#include <std_srvs/Trigger.h>
#include <sys/stat.h>

#include <stdexcept>
#include <utility>
#include <vector>

#include "grid_puzzle_localization/tile_geometry.hpp"
#include "point_cloud_msg.hpp"

namespace grid_puzzle_localization {
namespace {

bool isDirectory(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

}  // namespace

bool TileDeltaInput::inSequence(const TileDelta& msg) {
  switch (sequence_.accept(msg.revision, msg.reset)) {
    case TileDeltaSequence::Verdict::kIgnore:
      return false;
    case TileDeltaSequence::Verdict::kRequestResend: {
      ROS_WARN_NAMED(log_name_,
                     "tile_delta revision %u does not follow the last one applied: asking %s for the whole window",
                     msg.revision, resend_.getService().c_str());
      std_srvs::Trigger srv;
      if (!resend_.call(srv) || !srv.response.success) {
        sequence_.resendFailed();
        ROS_ERROR_THROTTLE_NAMED(5.0, log_name_, "service %s failed (%s); is the tile provider running?",
                                 resend_.getService().c_str(), srv.response.message.c_str());
      }
      return false;
    }
    case TileDeltaSequence::Verdict::kApply:
      break;
  }
  return true;
}

std::optional<MapChange> TileDeltaInput::accept(const TileDelta& msg, const MapUpdateWorker& map) {
  const bool by_reference = !msg.tile_dir.empty();
  if (!by_reference && msg.added_ids.size() != msg.added_clouds.size()) {
    ROS_ERROR_NAMED(log_name_,
                    "tile_delta revision %u: %zu added ids but %zu clouds; the provider must send one cloud per id",
                    msg.revision, msg.added_ids.size(), msg.added_clouds.size());
    return std::nullopt;
  }
  if (!inSequence(msg)) return std::nullopt;
  if (voxelsPerTileSide(msg.grid_size, ndt_resolution_) == 0)
    ROS_WARN_ONCE_NAMED(
        log_name_,
        "tile side %g m is not a whole multiple of ~ndt/resolution %g m: voxels straddle tiles, so each tile's "
        "statistics are kept as well (more memory per voxel); use a resolution that divides the tile side",
        msg.grid_size, ndt_resolution_);
  // A URL (map store) is checked by the map worker, which fetches from it.
  if (by_reference && !isMapStoreUrl(msg.tile_dir) && !isDirectory(msg.tile_dir)) {
    // Checked here, not only by the map worker, so the deltas missed meanwhile are made up by a resend.
    sequence_.notApplied();
    ROS_ERROR_THROTTLE_NAMED(
        5.0, log_name_,
        "tile_delta revision %u: tile directory '%s' does not exist (removed or unmounted?); "
        "matching on the %zu tiles loaded, the whole window is asked for again with the next delta",
        msg.revision, msg.tile_dir.c_str(), map.stats().tiles);
    return std::nullopt;
  }
  if (by_reference) {  // the map worker reads the files
    const double s = msg.grid_size;
    const MapExtent window{cellLow(msg.i_min, s), cellLow(msg.i_max + 1, s), cellLow(msg.j_min, s),
                           cellLow(msg.j_max + 1, s)};
    return MapChange::tileFiles(s, {msg.tile_dir, msg.index_revision, msg.reset != 0, msg.added_ids, msg.removed_ids,
                                    msg.prefetch_ids, window});
  }
  try {
    std::vector<TileCloud> added(msg.added_ids.size());
    for (std::size_t i = 0; i < added.size(); ++i) added[i] = {msg.added_ids[i], fromMsg(msg.added_clouds[i])};
    return MapChange::tiles(msg.reset, msg.grid_size, std::move(added), msg.removed_ids);
  } catch (const std::invalid_argument& e) {
    ROS_ERROR_NAMED(log_name_, "tile_delta revision %u: %s", msg.revision, e.what());
    return std::nullopt;
  }
}

}  // namespace grid_puzzle_localization
