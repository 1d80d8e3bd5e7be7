#include "tools/point_options.hpp"

#include <charconv>
#include <string>
#include <vector>

namespace tetstream::cli {
namespace {

// "a,b,c" -> {"a", "b", "c"} (empty fields kept, so validate() can name them).
std::vector<std::string> split_commas(const std::string& v) {
  std::vector<std::string> out;
  std::size_t start = 0;
  for (;;) {
    const std::size_t comma = v.find(',', start);
    out.push_back(v.substr(start, comma - start));
    if (comma == std::string::npos) return out;
    start = comma + 1;
  }
}

}  // namespace

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
         "Input format: raw, f32, f64 (raw float32/float64 xyz records), ply, npy, text, las, hdf5.\n"
         "Default: from the extension (.f32; .f64/.raw/.bin; .ply; .npy; .txt/.csv/.xyz/.pts/.asc;\n"
         ".las; .hdf5/.h5), else recognised from the first bytes (PLY, npy, LAS, HDF5, text)")
      ->group(group);
  app->add_option_function<std::string>(
         "--type",
         [&options](const std::string& v) {
           if (v == "f32" || v == "float32")
             options.type = io::ScalarType::kFloat32;
           else if (v == "f64" || v == "float64")
             options.type = io::ScalarType::kFloat64;
           else
             throw CLI::ValidationError("--type", "expected f32 or f64, got '" + v + "'");
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
         "--columns",
         [&options](const std::string& v) {
           options.columns.clear();
           for (const auto& f : split_commas(v)) {
             std::uint64_t c = 0;
             const auto r = std::from_chars(f.data(), f.data() + f.size(), c);
             if (f.empty() || r.ec != std::errc() || r.ptr != f.data() + f.size())
               throw UsageError("--columns: '" + f + "' is not a column number (1, 2, ...)");
             options.columns.push_back(c);
           }
           options.validate();  // a UsageError: one line, exit 2
         },
         "Text and npy input: the columns of x,y,z, counted from 1 (e.g. 2,3,4 skips an id column);\n"
         "default: the input has exactly three")
      ->group(group);
  app->add_option_function<std::string>(
         "--properties",
         [&options](const std::string& v) {
           options.properties = split_commas(v);
           options.validate();  // a UsageError: one line, exit 2
         },
         "PLY input: the vertex properties of x,y,z (default x,y,z, else X,Y,Z)")
      ->group(group);
  app->add_option("--dataset", options.datasets,
                  "HDF5 input: an (N, 3) float dataset to read, e.g. /PartType1/Coordinates; repeat for several\n"
                  "(read in the order given); `info FILE.hdf5` lists the candidates")
      ->expected(1)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll)
      ->group(group);
  app->add_option_function<std::string>(
         "--las-classes",
         [&options](const std::string& v) {
           options.las_classes.clear();
           for (const auto& f : split_commas(v)) {
             unsigned c = 0;
             const auto r = std::from_chars(f.data(), f.data() + f.size(), c);
             if (f.empty() || r.ec != std::errc() || r.ptr != f.data() + f.size() || c > 255)
               throw UsageError("--las-classes: '" + f + "' is not a classification code (0-255)");
             options.las_classes.push_back(std::uint8_t(c));
           }
         },
         "LAS input: keep only the points of these ASPRS classification codes, e.g. 2,6 (ground,\n"
         "buildings); part of the job: a resume with other classes is refused")
      ->group(group);
  app->add_option_function<std::string>(
         "--las-returns",
         [&options](const std::string& v) {
           using R = io::PointReadOptions::LasReturns;
           if (v == "all")
             options.las_returns = R::kAll;
           else if (v == "first")
             options.las_returns = R::kFirst;
           else if (v == "last")
             options.las_returns = R::kLast;
           else
             throw UsageError("--las-returns: expected last, first or all, got '" + v + "'");
         },
         "LAS input: keep only last returns (return number = number of returns), first returns\n"
         "(return number 1), or all (default)")
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

CLI::Option* add_point_input_files(CLI::App* app, const std::string& name, std::string& first,
                                   io::PointReadOptions& options, const std::string& help) {
  return app
      ->add_option_function<std::vector<std::string>>(
          name,
          [&first, &options](const std::vector<std::string>& args) {
            const std::vector<std::string> files = io::expand_inputs(args);
            first = files.front();
            options.more_inputs.assign(files.begin() + 1, files.end());
          },
          help)
      ->required();
}

}  // namespace tetstream::cli
