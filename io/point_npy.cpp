// NumPy .npy, format versions 1, 2 and 3: a float32 or float64 array of shape (N, 3)
// in C order, either byte order; or (N, C), C >= 3, with three columns chosen by
// --columns (1-based). Nothing may follow the array.
//   "\x93NUMPY" major minor  header_len (uint16 LE for v1, uint32 LE for v2/v3)
//   header: a Python dict literal {'descr': '<f8', 'fortran_order': False, 'shape': (N, 3), }
//   padded with spaces and a '\n' so the data starts on a 64-byte boundary.
#include "io/point_detail.hpp"

#include <charconv>
#include <vector>

namespace tetstream::io::detail {
namespace {

// The value text after `'key':` in the header dict, up to the next top-level ',' or '}'.
bool dict_value(std::string_view header, std::string_view key, std::string_view& value) {
  std::string quoted1(1, '\''), quoted2(1, '"');  // (built by appending: GCC 12 warns on "'" + s)
  quoted1.append(key).push_back('\'');
  quoted2.append(key).push_back('"');
  std::size_t k = header.find(quoted1);
  std::size_t klen = quoted1.size();
  if (k == std::string_view::npos) {
    k = header.find(quoted2);
    klen = quoted2.size();
  }
  if (k == std::string_view::npos) return false;
  std::size_t i = header.find(':', k + klen);
  if (i == std::string_view::npos) return false;
  ++i;
  while (i < header.size() && header[i] == ' ') ++i;
  std::size_t j = i;
  int depth = 0;
  while (j < header.size()) {
    const char c = header[j];
    if (c == '(' || c == '[')
      ++depth;
    else if (c == ')' || c == ']')
      --depth;
    else if ((c == ',' || c == '}') && depth == 0)
      break;
    ++j;
  }
  value = header.substr(i, j - i);
  while (!value.empty() && value.back() == ' ') value.remove_suffix(1);
  return true;
}

}  // namespace

std::unique_ptr<PointReader> open_npy(std::unique_ptr<ByteSource> src, const PointReadOptions& options) {
  const std::string& file = src->name();
  if (src->ensure(10) == 0) throw InputError::at_byte(file, 0, "empty file: no points");
  if (src->available() < 10 || std::memcmp(src->data(), "\x93NUMPY", 6) != 0) {
    throw InputError::at_byte(file, 0, "not a .npy file: it does not start with the \\x93NUMPY magic");
  }
  const auto* b = reinterpret_cast<const unsigned char*>(src->data());
  const int major = b[6];
  std::uint64_t header_len = 0, header_start = 0;
  if (major == 1) {
    header_len = b[8] | (std::uint64_t(b[9]) << 8);
    header_start = 10;
  } else if (major == 2 || major == 3) {
    if (src->ensure(12) < 12) throw InputError::at_byte(file, src->available(), "truncated .npy preamble");
    b = reinterpret_cast<const unsigned char*>(src->data());
    header_len = b[8] | (std::uint64_t(b[9]) << 8) | (std::uint64_t(b[10]) << 16) | (std::uint64_t(b[11]) << 24);
    header_start = 12;
  } else {
    throw InputError::at_byte(file, 6, "unsupported .npy format version " + std::to_string(major));
  }
  if (header_len > (std::uint64_t(1) << 20)) {
    throw InputError::at_byte(file, 8, "implausible .npy header length " + std::to_string(header_len));
  }
  const std::size_t total = static_cast<std::size_t>(header_start + header_len);
  if (src->ensure(total) < total) {
    throw InputError::at_byte(file, src->available(),
                              "truncated .npy header: " + std::to_string(header_len) + " bytes promised");
  }
  const std::string header(src->data() + header_start, static_cast<std::size_t>(header_len));
  src->consume(total);
  auto bad = [&](const std::string& problem) {
    return InputError::at_byte(file, header_start,
                               problem + " in .npy header " + std::string(header.substr(0, header.find('}') + 1)));
  };

  std::string_view descr, fortran, shape;
  if (!dict_value(header, "descr", descr) || !dict_value(header, "fortran_order", fortran) ||
      !dict_value(header, "shape", shape)) {
    throw bad("missing 'descr', 'fortran_order' or 'shape'");
  }
  // descr: a quoted type string such as '<f8'; a list means a structured dtype.
  if (descr.size() < 2 || (descr.front() != '\'' && descr.front() != '"')) {
    throw bad("unsupported dtype " + std::string(descr) + " (need float32 or float64)");
  }
  const std::string_view dt = descr.substr(1, descr.size() - 2);
  Scalar type;
  bool big;
  if (dt.size() == 3 && (dt[1] == 'f') && (dt[2] == '4' || dt[2] == '8') &&
      (dt[0] == '<' || dt[0] == '>' || dt[0] == '=')) {
    type = dt[2] == '4' ? Scalar::kF32 : Scalar::kF64;
    big = dt[0] == '>' || (dt[0] == '=' && !kHostLittle);
  } else {
    throw bad("unsupported dtype '" + std::string(dt) + "' (need float32 or float64: <f4 <f8 >f4 >f8)");
  }
  if (fortran == "True") throw bad("fortran_order is True (need C order; save with np.ascontiguousarray)");
  if (fortran != "False") throw bad("unreadable fortran_order " + std::string(fortran));

  // shape: "(N, 3)" exactly two dimensions, the second 3.
  std::vector<std::uint64_t> dims;
  if (shape.size() < 2 || shape.front() != '(' || shape.back() != ')') throw bad("unreadable shape");
  {
    std::string_view s = shape.substr(1, shape.size() - 2);
    std::size_t i = 0;
    while (i < s.size()) {
      while (i < s.size() && (s[i] == ' ' || s[i] == ',')) ++i;
      if (i == s.size()) break;
      std::uint64_t d = 0;
      const auto r = std::from_chars(s.data() + i, s.data() + s.size(), d);
      if (r.ec != std::errc()) throw bad("unreadable shape");
      dims.push_back(d);
      i = static_cast<std::size_t>(r.ptr - s.data());
      while (i < s.size() && s[i] == 'L') ++i;  // Python 2 longs
    }
  }
  const std::vector<std::uint64_t>& columns = options.columns;
  if (dims.size() != 2 || (columns.empty() && dims[1] != 3)) {
    throw bad("shape " + std::string(shape) + " is not (N, 3)" +
              (dims.size() == 2 && dims[1] > 3 ? " (choose three columns with --columns)" : ""));
  }
  for (std::uint64_t c : columns) {
    if (c > dims[1]) {
      throw UsageError("--columns " + std::to_string(c) + ": " + file + " has " + std::to_string(dims[1]) +
                       " columns (shape " + std::string(shape) + ")");
    }
  }

  BinaryLayout layout;
  const std::uint64_t w = scalar_size(type);
  layout.data_start = total;
  if (!checked_mul(dims[1], w, layout.stride)) throw bad("row size of shape " + std::string(shape) + " overflows");
  for (int c = 0; c < 3; ++c) {
    layout.offset[c] = (columns.empty() ? std::uint64_t(c) : columns[c] - 1) * w;
    layout.type[c] = type;
  }
  layout.tail = BinaryLayout::Tail::kNothing;  // the format has nothing after the array
  layout.big_endian = big;
  layout.record = "row";
  layout.records = "rows";
  std::string name = "npy " + std::string(dt);
  if (!columns.empty()) {
    name +=
        " columns " + std::to_string(columns[0]) + "," + std::to_string(columns[1]) + "," + std::to_string(columns[2]);
  }
  return make_binary_reader(std::move(src), layout, dims[0], /*promised=*/true, std::move(name));
}

}  // namespace tetstream::io::detail
