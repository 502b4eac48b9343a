// Private helper of the core: a symmetric 3x3 matrix kept as its six distinct entries, in the order xx xy xz yy yz zz
// (the voxel sums of squares, the NDT's second-order terms).
#pragma once

namespace grid_puzzle_localization::packed_symmetric {

constexpr int kRow[6] = {0, 0, 0, 1, 1, 2};                      ///< row of packed entry e
constexpr int kCol[6] = {0, 1, 2, 1, 2, 2};                      ///< column of packed entry e
constexpr int kIndex[3][3] = {{0, 1, 2}, {1, 3, 4}, {2, 4, 5}};  ///< packed entry of (row, column)

}  // namespace grid_puzzle_localization::packed_symmetric
