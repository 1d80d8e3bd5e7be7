// PLY: the `vertex` element's x, y, z (or X, Y, Z, or the --properties named), any
// numeric property type, binary (either byte order) or ASCII. Other properties of vertex
// are skipped, and so are other elements before and after it (list properties
// included); after the last element the file must end.
#include "io/point_detail.hpp"

#include <algorithm>
#include <charconv>
#include <vector>

namespace tetstream::io::detail {
namespace {

enum class PlyEncoding { kAscii, kBinaryLittle, kBinaryBig };

struct PlyProperty {
  std::string name;
  bool is_list = false;
  Scalar type = Scalar::kF64;       // scalar type, or the item type of a list
  Scalar count_type = Scalar::kU8;  // list length type
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::uint64_t header_line = 0;
  std::vector<PlyProperty> props;
  bool has_list() const {
    for (const auto& p : props)
      if (p.is_list) return true;
    return false;
  }
  std::uint64_t record_bytes() const {  // fixed-size elements only
    std::uint64_t s = 0;
    for (const auto& p : props) s += scalar_size(p.type);
    return s;
  }
};

bool parse_scalar_type(std::string_view s, Scalar& t) {
  static const std::pair<std::string_view, Scalar> table[] = {
      {"char", Scalar::kI8},   {"int8", Scalar::kI8},     {"uchar", Scalar::kU8},   {"uint8", Scalar::kU8},
      {"short", Scalar::kI16}, {"int16", Scalar::kI16},   {"ushort", Scalar::kU16}, {"uint16", Scalar::kU16},
      {"int", Scalar::kI32},   {"int32", Scalar::kI32},   {"uint", Scalar::kU32},   {"uint32", Scalar::kU32},
      {"float", Scalar::kF32}, {"float32", Scalar::kF32}, {"double", Scalar::kF64}, {"float64", Scalar::kF64}};
  for (const auto& [name, type] : table) {
    if (s == name) {
      t = type;
      return true;
    }
  }
  return false;
}

std::vector<std::string_view> split_words(std::string_view line) {
  std::vector<std::string_view> words;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    std::size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t') ++j;
    if (j > i) words.push_back(line.substr(i, j - i));
    i = j;
  }
  return words;
}

// Reads one unsigned list length of type t from the source (binary).
std::uint64_t read_list_length(ByteSource& src, Scalar t, bool big_endian) {
  const std::size_t w = scalar_size(t);
  if (src.ensure(w) < w) throw InputError::at_byte(src.name(), src.offset(), "truncated inside a list property");
  unsigned char b[8];
  std::memcpy(b, src.data(), w);
  src.consume(w);
  if (big_endian != !kHostLittle) std::reverse(b, b + w);
  std::int64_t v = 0;
  switch (t) {
    case Scalar::kI8: {
      std::int8_t x;
      std::memcpy(&x, b, 1);
      v = x;
      break;
    }
    case Scalar::kU8:
      v = b[0];
      break;
    case Scalar::kI16: {
      std::int16_t x;
      std::memcpy(&x, b, 2);
      v = x;
      break;
    }
    case Scalar::kU16: {
      std::uint16_t x;
      std::memcpy(&x, b, 2);
      v = x;
      break;
    }
    case Scalar::kI32: {
      std::int32_t x;
      std::memcpy(&x, b, 4);
      v = x;
      break;
    }
    case Scalar::kU32: {
      std::uint32_t x;
      std::memcpy(&x, b, 4);
      v = x;
      break;
    }
    default:
      throw InputError::at_byte(src.name(), src.offset(), "list length type must be an integer");
  }
  if (v < 0) throw InputError::at_byte(src.name(), src.offset() - w, "negative list length");
  return static_cast<std::uint64_t>(v);
}

void skip_exactly(ByteSource& src, std::uint64_t n, const std::string& what) {
  const std::uint64_t start = src.offset();
  if (src.skip(n) < n) {
    throw InputError::at_byte(
        src.name(), src.offset(),
        "truncated: input ends inside " + what + " (started at byte " + std::to_string(start) + ")");
  }
}

// Skips a binary element (one before vertex, or after it when checking the tail).
void skip_binary_element(ByteSource& src, const PlyElement& e, bool big_endian) {
  if (!e.has_list()) {
    std::uint64_t bytes = 0;
    if (!checked_mul(e.count, e.record_bytes(), bytes)) {
      throw InputError::at_byte(src.name(), src.offset(),
                                "element '" + e.name + "': " + std::to_string(e.count) + " records of " +
                                    std::to_string(e.record_bytes()) + " bytes: more than any file can hold");
    }
    skip_exactly(src, bytes, "element '" + e.name + "'");
    return;
  }
  for (std::uint64_t r = 0; r < e.count; ++r) {
    for (const auto& p : e.props) {
      if (p.is_list) {
        const std::uint64_t len = read_list_length(src, p.count_type, big_endian);
        skip_exactly(src, len * scalar_size(p.type), "a list of element '" + e.name + "'");
      } else {
        skip_exactly(src, scalar_size(p.type), "element '" + e.name + "'");
      }
    }
  }
}

// The vertex properties that hold x, y, z: the names given (--properties), else x, y, z,
// else X, Y, Z (LAS-derived clouds). Throws naming what the element does have.
void find_coordinates(const std::string& file, const PlyElement& vertex, const std::vector<std::string>& wanted,
                      int index[3]) {
  for (const auto& p : vertex.props) {
    if (p.is_list) {
      throw InputError::at_line(file, vertex.header_line,
                                "vertex element has a list property '" + p.name + "': not supported");
    }
  }
  auto find = [&](const std::string& name) {
    for (std::size_t k = 0; k < vertex.props.size(); ++k)
      if (vertex.props[k].name == name) return int(k);
    return -1;
  };
  std::vector<std::string> names = wanted;
  if (names.empty()) {
    names = {"x", "y", "z"};
    if (find("x") < 0 && find("y") < 0 && find("z") < 0 && find("X") >= 0) names = {"X", "Y", "Z"};
  }
  for (int c = 0; c < 3; ++c) {
    index[c] = find(names[c]);
    if (index[c] >= 0) continue;
    std::string have;
    for (const auto& p : vertex.props) have += (have.empty() ? "" : ", ") + p.name;
    throw InputError::at_line(
        file, vertex.header_line,
        "vertex element has no '" + names[c] + "' property (it has: " + have + "; choose with --properties)");
  }
}

class PlyAsciiReader final : public PointReader {
 public:
  // `after_lines`: the records (one non-blank line each) of the elements after vertex.
  PlyAsciiReader(std::unique_ptr<ByteSource> src, std::unique_ptr<LineSource> lines, std::uint64_t count,
                 std::size_t nprops, const int index[3], std::uint64_t after_lines)
      : src_(std::move(src)), lines_(std::move(lines)), nprops_(nprops), after_lines_(after_lines) {
    count_ = count;
    format_name_ = "ply ascii";
    source_name_ = src_->name();
    for (int c = 0; c < 3; ++c) index_[c] = index[c];
    values_.resize(nprops_);
  }

  std::size_t read(double* xyz, std::size_t max_points) override {
    if (line_of_.size() < max_points) line_of_.resize(max_points);
    chunk_first_ = points_read_;
    std::size_t n = 0;
    std::string_view line, bad;
    while (n < max_points && points_read_ + n < *count_) {
      if (!lines_->next(line)) {
        throw InputError::at_line(source_name_, lines_->line_number() + 1,
                                  "truncated: input ends after " + std::to_string(points_read_ + n) +
                                      " vertices, but the header promises " + std::to_string(*count_));
      }
      const std::uint64_t ln = lines_->line_number();
      const int fields = parse_numbers(line, values_.data(), int(nprops_), bad);
      if (fields == 0) continue;
      if (fields < 0)
        throw InputError::at_line(source_name_, ln, "not a number: '" + std::string(bad.substr(0, 40)) + "'");
      if (std::size_t(fields) != nprops_) {
        throw InputError::at_line(
            source_name_, ln,
            "expected " + std::to_string(nprops_) + " vertex properties, found " + std::to_string(fields));
      }
      for (int c = 0; c < 3; ++c) {
        const double v = values_[index_[c]];
        if (!std::isfinite(v)) {
          throw InputError::at_line(source_name_, ln,
                                    std::string("non-finite coordinate (") + "xyz"[c] + " = " +
                                        (std::isnan(v) ? "nan"
                                         : v > 0       ? "inf"
                                                       : "-inf") +
                                        ")");
        }
        xyz[3 * n + c] = v;
      }
      line_of_[n++] = ln;
    }
    points_read_ += n;
    if (points_read_ == *count_ && !tail_checked_) {
      tail_checked_ = true;
      check_tail();
    }
    return n;
  }

  std::uint64_t bytes_read() const override { return src_->offset(); }
  std::optional<std::uint64_t> source_size() const override { return src_->size(); }
  std::string location(std::uint64_t index) const override {
    if (index >= chunk_first_ && index < points_read_) return "line " + std::to_string(line_of_[index - chunk_first_]);
    return "vertex " + std::to_string(index);
  }

 private:
  // After the last vertex: the records of the later elements, then only blank lines.
  void check_tail() {
    std::string_view line;
    for (std::uint64_t r = 0; r < after_lines_;) {
      if (!lines_->next(line)) {
        throw InputError::at_line(source_name_, lines_->line_number() + 1,
                                  "truncated: input ends inside the elements after vertex");
      }
      if (line.find_first_not_of(" \t") != std::string_view::npos) ++r;
    }
    while (lines_->next(line)) {
      if (line.find_first_not_of(" \t") != std::string_view::npos) {
        throw InputError::at_line(
            source_name_, lines_->line_number(),
            "trailing data after the last element the header declares (a wrong count in the header?)");
      }
    }
  }

  std::unique_ptr<ByteSource> src_;
  std::unique_ptr<LineSource> lines_;
  std::size_t nprops_;
  std::uint64_t after_lines_ = 0;
  bool tail_checked_ = false;
  int index_[3];
  std::vector<double> values_;
  std::uint64_t chunk_first_ = 0;
  std::vector<std::uint64_t> line_of_;
};

}  // namespace

std::unique_ptr<PointReader> open_ply(std::unique_ptr<ByteSource> src, const PointReadOptions& options) {
  const std::string& file = src->name();
  if (src->ensure(4) < 4 || std::memcmp(src->data(), "ply", 3) != 0 ||
      (src->data()[3] != '\n' && src->data()[3] != '\r')) {
    if (src->available() == 0) throw InputError::at_byte(file, 0, "empty file: no points");
    throw InputError::at_byte(file, 0, "not a PLY file: it does not start with the 'ply' magic line");
  }
  auto lines = std::make_unique<LineSource>(*src);
  std::string_view line;
  lines->next(line);  // "ply"

  PlyEncoding encoding = PlyEncoding::kAscii;
  bool have_format = false, ended = false;
  std::vector<PlyElement> elements;
  while (!ended) {
    if (src->offset() > LineSource::kMaxLine) {
      throw InputError::at_byte(file, src->offset(), "PLY header has no end_header in its first 1 MiB");
    }
    if (!lines->next(line)) {
      throw InputError::at_line(file, lines->line_number() + 1, "truncated PLY header: no end_header");
    }
    const std::uint64_t ln = lines->line_number();
    const auto w = split_words(line);
    if (w.empty()) continue;
    if (w[0] == "comment" || w[0] == "obj_info") continue;
    if (w[0] == "end_header") {
      ended = true;
    } else if (w[0] == "format") {
      if (w.size() < 2) throw InputError::at_line(file, ln, "PLY format line without an encoding");
      if (w[1] == "ascii")
        encoding = PlyEncoding::kAscii;
      else if (w[1] == "binary_little_endian")
        encoding = PlyEncoding::kBinaryLittle;
      else if (w[1] == "binary_big_endian")
        encoding = PlyEncoding::kBinaryBig;
      else
        throw InputError::at_line(file, ln, "unknown PLY format '" + std::string(w[1]) + "'");
      have_format = true;
    } else if (w[0] == "element") {
      if (w.size() != 3) throw InputError::at_line(file, ln, "malformed element line (expected: element NAME COUNT)");
      PlyElement e;
      e.name = std::string(w[1]);
      e.header_line = ln;
      const auto r = std::from_chars(w[2].data(), w[2].data() + w[2].size(), e.count);
      if (r.ec != std::errc() || r.ptr != w[2].data() + w[2].size()) {
        throw InputError::at_line(file, ln, "element count '" + std::string(w[2]) + "' is not a non-negative integer");
      }
      elements.push_back(std::move(e));
    } else if (w[0] == "property") {
      if (elements.empty()) throw InputError::at_line(file, ln, "property before any element");
      PlyProperty p;
      if (w.size() == 5 && w[1] == "list") {
        p.is_list = true;
        if (!parse_scalar_type(w[2], p.count_type) || !parse_scalar_type(w[3], p.type))
          throw InputError::at_line(file, ln, "unknown PLY property type in '" + std::string(line) + "'");
        p.name = std::string(w[4]);
      } else if (w.size() == 3) {
        if (!parse_scalar_type(w[1], p.type))
          throw InputError::at_line(file, ln, "unknown PLY property type '" + std::string(w[1]) + "'");
        p.name = std::string(w[2]);
      } else {
        throw InputError::at_line(file, ln, "malformed property line '" + std::string(line) + "'");
      }
      elements.back().props.push_back(std::move(p));
    } else {
      throw InputError::at_line(file, ln, "unknown PLY header keyword '" + std::string(w[0]) + "'");
    }
  }
  const std::uint64_t header_end_line = lines->line_number();
  if (!have_format) throw InputError::at_line(file, 2, "PLY header has no format line");

  std::size_t vi = elements.size();
  for (std::size_t i = 0; i < elements.size(); ++i)
    if (elements[i].name == "vertex") {
      vi = i;
      break;
    }
  if (vi == elements.size()) throw InputError::at_line(file, header_end_line, "PLY header has no 'vertex' element");
  const PlyElement& vertex = elements[vi];
  int index[3];
  find_coordinates(file, vertex, options.properties, index);
  if (vertex.count == 0) {
    throw InputError::at_line(file, vertex.header_line, "the header declares 0 vertices: no points");
  }

  if (encoding == PlyEncoding::kAscii) {
    // Skip the records (one per line) of the elements before vertex.
    for (std::size_t i = 0; i < vi; ++i) {
      for (std::uint64_t r = 0; r < elements[i].count;) {
        if (!lines->next(line)) {
          throw InputError::at_line(file, lines->line_number() + 1,
                                    "truncated: input ends inside element '" + elements[i].name + "'");
        }
        if (line.find_first_not_of(" \t") != std::string_view::npos) ++r;
      }
    }
    std::uint64_t after_lines = 0;
    for (std::size_t i = vi + 1; i < elements.size(); ++i) {
      if (!checked_add(after_lines, elements[i].count, after_lines))
        throw InputError::at_line(file, elements[i].header_line, "element counts overflow");
    }
    return std::make_unique<PlyAsciiReader>(std::move(src), std::move(lines), vertex.count, vertex.props.size(), index,
                                            after_lines);
  }

  const bool big = encoding == PlyEncoding::kBinaryBig;
  for (std::size_t i = 0; i < vi; ++i) skip_binary_element(*src, elements[i], big);
  BinaryLayout layout;
  layout.data_start = src->offset();
  layout.stride = vertex.record_bytes();
  std::uint64_t off = 0;
  for (std::size_t k = 0; k < vertex.props.size(); ++k) {
    for (int c = 0; c < 3; ++c) {
      if (int(k) == index[c]) {
        layout.offset[c] = off;
        layout.type[c] = vertex.props[k].type;
      }
    }
    off += scalar_size(vertex.props[k].type);
  }
  layout.big_endian = big;
  layout.record = "vertex";
  layout.records = "vertices";
  if (vi + 1 == elements.size()) {
    layout.tail = BinaryLayout::Tail::kNothing;
  } else {
    layout.tail = BinaryLayout::Tail::kChecked;
    std::vector<PlyElement> later(elements.begin() + std::ptrdiff_t(vi) + 1, elements.end());
    layout.after = [later = std::move(later), big](ByteSource& s) {
      for (const PlyElement& e : later) skip_binary_element(s, e, big);
      expect_end(s, "last element the header declares");
    };
  }
  std::string name = big ? "ply binary_big_endian" : "ply binary_little_endian";
  lines.reset();
  return make_binary_reader(std::move(src), layout, vertex.count, /*promised=*/true, std::move(name));
}

}  // namespace tetstream::io::detail
