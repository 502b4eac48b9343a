// index.json's per-tile file, size and SHA-256 as the C++ reader parses them (parseTileIndex), against the texts
// `gpm tile` writes with and without checksums (test_tiling.py holds the writer to the same schema).
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

#include "grid_puzzle_localization/map_store/map_store.hpp"
#include "grid_puzzle_localization/provider/tile_directory.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

const std::string kA(64, 'a');
const std::string kB = "0123456789abcdef0123456789abcdef0123456789abcdef0123456789abcdef";

std::string tile(int i, const std::string& file, int bytes, const std::string& sha) {
  return R"({"key":[)" + std::to_string(i) + R"(,0],"stem":"x","file":")" + file +
         R"(","center":[1.0,1.0],"points":1,"bounds":{"min":[0.5,0.5,0.0],"max":[0.5,0.5,0.0]},"bytes":)" +
         std::to_string(bytes) + R"(,"data_bytes":12)" + (sha.empty() ? "" : R"(,"sha256":")" + sha + "\"") + "}";
}

std::string index(const std::string& tiles) {
  return R"({"format":"grid_puzzle_tiles","version":1,"grid_size":2.0,"origin":[0.0,0.0],"fields":[],)"
         R"("record_bytes":12,"points":2,"nonfinite_dropped":0,"inputs":[],"tiles":[)" +
         tiles + "]}";
}

}  // namespace

TEST(TileIndex, ReadsEachTilesFileSizeAndChecksum) {
  const gpl::TileIndexListing listing =
      gpl::parseTileIndex(index(tile(0, "1.0_1.0.pcd", 200, kA) + "," + tile(1, "3.0_1.0.pcd", 212, kB)), "t");
  ASSERT_EQ(listing.tiles.size(), 2u);
  EXPECT_EQ(listing.grid_size, 2.0);
  EXPECT_TRUE(listing.checksums());
  EXPECT_EQ(listing.tiles[0].file, "1.0_1.0.pcd");
  EXPECT_EQ(listing.tiles[0].bytes, 200u);
  EXPECT_EQ(listing.tiles[0].sha256, kA);
  EXPECT_EQ(listing.tiles[1].file, "3.0_1.0.pcd");
  EXPECT_EQ(listing.tiles[1].bytes, 212u);
  EXPECT_EQ(listing.tiles[1].sha256, kB);
  EXPECT_EQ(listing.keys.size(), 2u);
}

TEST(TileIndex, AnIndexWithoutChecksumsStaysReadable) {
  const gpl::TileIndexListing listing = gpl::parseTileIndex(index(tile(0, "1.0_1.0.pcd", 200, "")), "old");
  ASSERT_EQ(listing.tiles.size(), 1u);
  EXPECT_FALSE(listing.checksums());
  EXPECT_EQ(listing.tiles[0].sha256, "");
  EXPECT_EQ(listing.tiles[0].bytes, 200u);
}

TEST(TileIndex, RefusesAPartialOrMalformedChecksumColumnNamingTheIndex) {
  const auto message = [](const std::string& text) {
    try {
      gpl::parseTileIndex(text, "http://host/map/index.json");
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  const std::string partial = message(index(tile(0, "1.0_1.0.pcd", 1, kA) + "," + tile(1, "3.0_1.0.pcd", 1, "")));
  EXPECT_NE(partial.find("http://host/map/index.json"), std::string::npos) << partial;
  EXPECT_NE(partial.find("some tiles have a sha256"), std::string::npos) << partial;
  const std::string upper = message(index(tile(0, "1.0_1.0.pcd", 1, std::string(64, 'A'))));
  EXPECT_NE(upper.find("not 64 lowercase hex"), std::string::npos) << upper;
  const std::string negative = message(index(tile(0, "1.0_1.0.pcd", -3, kA)));
  EXPECT_NE(negative.find("bytes"), std::string::npos) << negative;
  EXPECT_NE(message("{").find("not a readable tile index"), std::string::npos);
}

TEST(TileIndex, Sha256OfKnownTexts) {
  // FIPS 180-2 examples.
  EXPECT_EQ(gpl::sha256Hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(gpl::sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
}
