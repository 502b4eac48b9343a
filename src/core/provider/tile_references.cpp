#include "grid_puzzle_localization/provider/tile_references.hpp"

#include <algorithm>
#include <stdexcept>

namespace grid_puzzle_localization {
namespace {

std::vector<TileKey> decodeAll(const std::vector<std::uint64_t>& codes) {
  std::vector<TileKey> keys;
  keys.reserve(codes.size());
  for (const std::uint64_t c : codes) keys.push_back(decodeTileKey(c));
  return keys;
}

}  // namespace

std::vector<TileBox> boxMinus(const TileBox& a, const TileBox& b) {
  const TileBox in{std::max(a.i_min, b.i_min), std::min(a.i_max, b.i_max), std::max(a.j_min, b.j_min),
                   std::min(a.j_max, b.j_max)};
  if (in.empty()) return {a};
  const TileBox strips[4] = {{a.i_min, in.i_min - 1, a.j_min, a.j_max},
                             {in.i_max + 1, a.i_max, a.j_min, a.j_max},
                             {in.i_min, in.i_max, a.j_min, in.j_min - 1},
                             {in.i_min, in.i_max, in.j_max + 1, a.j_max}};
  std::vector<TileBox> out;
  for (const TileBox& s : strips)
    if (!s.empty()) out.push_back(s);
  return out;
}

TileReferences::TileReferences(TileDirectory directory)
    : directory_(std::move(directory)),
      revision_(directory_.remote ? directory_.remote->revision() : tileIndexRevision(directory_.path)) {}

std::vector<std::uint64_t> TileReferences::codesIn(const std::vector<TileBox>& boxes) const {
  std::vector<std::uint64_t> codes;
  for (const TileBox& b : boxes) directory_.tiles.codesInBox(b, codes);
  std::sort(codes.begin(), codes.end());
  return codes;
}

ReferenceDelta TileReferences::update(const TileBox& box, const std::vector<Window>& ahead) {
  // A window moves by a strip at a time: only the strips between the old and the new box are listed.
  std::vector<std::uint64_t> added, removed;
  if (!has_box_) {
    added = codesIn({box});
  } else {
    added = codesIn(boxMinus(box, box_));
    removed = codesIn(boxMinus(box_, box));
  }
  for (const std::uint64_t c : removed) loaded_.erase(c);
  loaded_.insert(added.begin(), added.end());
  box_ = box;
  has_box_ = true;
  std::vector<std::uint64_t> prefetch;
  std::unordered_set<std::uint64_t> named;
  for (const Window& w : ahead) {  // most likely window first
    for (const std::uint64_t c : codesIn(boxMinus(w.bounds(), box))) {
      if (!named.insert(c).second) continue;
      if (prefetch.size() < kPrefetchMaxTiles) prefetch.push_back(c);
    }
    if (prefetch.size() == kPrefetchMaxTiles) break;
  }
  return {decodeAll(added), decodeAll(removed), decodeAll(prefetch)};
}

std::vector<TileKey> TileReferences::loaded() const {
  std::vector<std::uint64_t> codes(loaded_.begin(), loaded_.end());
  std::sort(codes.begin(), codes.end());
  return decodeAll(codes);
}

bool TileReferences::refresh() {
  if (directory_.remote) {  // given by URL: the poller has fetched the newest index
    auto newer = directory_.remote->newerThan(revision_);
    if (!newer) return false;
    std::shared_ptr<RemoteTileIndex> remote = directory_.remote;
    directory_ = std::move(newer->first);
    directory_.remote = std::move(remote);
    revision_ = std::move(newer->second);
    loaded_.clear();
    has_box_ = false;
    return true;
  }
  std::string revision;
  try {
    revision = tileIndexRevision(directory_.path);
  } catch (const std::invalid_argument&) {
    throw std::invalid_argument("tile directory " + directory_.path +
                                " cannot be read any more; restore it or restart the provider with another tiles/dir");
  }
  if (revision == revision_) return false;
  directory_ = openTileDirectory(directory_.path, directory_.grid_size);
  revision_ = revision;
  loaded_.clear();
  has_box_ = false;
  return true;
}

}  // namespace grid_puzzle_localization
