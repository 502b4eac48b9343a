#include "map_store_params.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace grid_puzzle_localization {
namespace {

template <class T>
void load(const ros::NodeHandle& pnh, const std::string& name, T& field, const char* type) {
  if (!pnh.hasParam("map_store/" + name)) return;
  T value;
  if (!pnh.getParam("map_store/" + name, value))
    throw std::invalid_argument("parameter map_store/" + name + " must be a " + type);
  field = value;
}

// Byte counts: XmlRpc integers have 32 bits, so a float (5e9) is accepted too.
void loadBytes(const ros::NodeHandle& pnh, const std::string& name, std::uint64_t& field) {
  double value = static_cast<double>(field);
  load(pnh, name, value, "number of bytes");
  if (!(value >= 1.0 && value < 1.8e19 && std::isfinite(value)))
    throw std::invalid_argument("parameter map_store/" + name + " must be a positive number of bytes");
  field = static_cast<std::uint64_t>(value);
}

}  // namespace

MapStoreConfig loadMapStoreConfig(const ros::NodeHandle& pnh) {
  MapStoreConfig c;
  load(pnh, "cache_dir", c.cache_dir, "str");
  loadBytes(pnh, "cache_max_bytes", c.cache_max_bytes);
  load(pnh, "connect_timeout", c.connect_timeout, "float");
  load(pnh, "transfer_timeout", c.transfer_timeout, "float");
  load(pnh, "max_retries", c.max_retries, "int");
  load(pnh, "retry_backoff", c.retry_backoff, "float");
  load(pnh, "max_connections", c.max_connections, "int");
  loadBytes(pnh, "max_tile_bytes", c.max_tile_bytes);
  loadBytes(pnh, "max_index_bytes", c.max_index_bytes);
  load(pnh, "ca_file", c.ca_file, "str");
  load(pnh, "bearer_token_file", c.bearer_token_file, "str");
  load(pnh, "bearer_token_env", c.bearer_token_env, "str");
  load(pnh, "basic_auth_file", c.basic_auth_file, "str");
  load(pnh, "poll_period", c.poll_period, "float");
  const std::string problem = c.validate();
  if (!problem.empty()) throw std::invalid_argument(problem);
  return c;
}

}  // namespace grid_puzzle_localization
