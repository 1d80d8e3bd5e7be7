#include "tools/point_options.hpp"

#include <string>

namespace tetstream::cli {

void add_point_input_options(CLI::App* app, io::PointReadOptions& options) {
  const char* group = "Point input";
  app->add_option_function<std::string>(
         "--format",
         [&options](const std::string& v) {
           try {
             io::parse_format_name(v, options.format, options.type);
           } catch (const Error& e) {
             throw CLI::ValidationError("--format", e.what());
           }
         },
         "Input format: raw, f32, f64 (raw float32/float64 xyz records), ply, npy, text.\n"
         "Default: from the extension (.f32; .f64/.raw/.bin; .ply; .npy; .txt/.csv/.xyz/.pts/.asc),\n"
         "else recognised from the first bytes (PLY, npy, text)")
      ->group(group);
  app->add_option_function<std::string>(
         "--type",
         [&options](const std::string& v) {
           if (v == "f32" || v == "float32") options.type = io::ScalarType::kFloat32;
           else if (v == "f64" || v == "float64") options.type = io::ScalarType::kFloat64;
           else throw CLI::ValidationError("--type", "expected f32 or f64, got '" + v + "'");
         },
         "Raw input scalar type: f32 or f64 (default: from the extension, else f64)")
      ->group(group);
  app->add_option("--stride", options.stride,
                  "Raw input: bytes per record (default 3 x scalar size); for dumps that interleave other fields")
      ->check(CLI::NonNegativeNumber)
      ->group(group);
  app->add_option("--offset", options.offset, "Raw input: byte offset of x within a record (default 0)")
      ->check(CLI::NonNegativeNumber)
      ->group(group);
  app->add_option_function<std::string>(
         "--byte-order",
         [&options](const std::string& v) {
           try {
             options.byte_order = io::parse_byte_order(v);
           } catch (const Error& e) {
             throw CLI::ValidationError("--byte-order", e.what());
           }
         },
         "Raw input byte order: little (default) or big")
      ->group(group);
}

}  // namespace tetstream::cli
