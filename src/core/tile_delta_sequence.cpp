#include "grid_puzzle_localization/tile_delta_sequence.hpp"

namespace grid_puzzle_localization {

TileDeltaSequence::Verdict TileDeltaSequence::accept(std::uint32_t revision, bool reset) {
  if (reset) {
    synced_ = true;
    awaiting_reset_ = false;
    last_ = revision;
    return Verdict::kApply;
  }
  if (synced_ && revision == last_ + 1) {
    last_ = revision;
    return Verdict::kApply;
  }
  // Revisions wrap at 2^32 only after years at 10 Hz; unsigned difference keeps that case right.
  if (synced_ && static_cast<std::uint32_t>(revision - last_) > 0x80000000u) return Verdict::kIgnore;
  if (synced_ && revision == last_) return Verdict::kIgnore;
  synced_ = false;
  if (awaiting_reset_) return Verdict::kIgnore;
  awaiting_reset_ = true;
  return Verdict::kRequestResend;
}

}  // namespace grid_puzzle_localization
