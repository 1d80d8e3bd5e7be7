// Text points: one point per line, "x y z" or "x,y,z" (blanks, commas or semicolons),
// '#' comments, blank lines, and an optional header line (the first line with fields,
// if every field is a name: see is_header_line). With --columns, three chosen fields
// of a wider table. Numbers are parsed with std::from_chars.
#include "io/point_detail.hpp"

#include <cstring>
#include <cctype>
#include <charconv>
#include <vector>

namespace tetstream::io::detail {

bool LineSource::next(std::string_view& line) {
  std::size_t scanned = 0;  // bytes already known to hold no '\n'
  for (;;) {
    const char* p = src_.data();
    const std::size_t a = src_.available();
    const void* nl = scanned < a ? std::memchr(p + scanned, '\n', a - scanned) : nullptr;
    if (nl) {
      std::size_t len = static_cast<const char*>(nl) - p;
      src_.consume(len + 1);
      if (len > 0 && p[len - 1] == '\r') --len;
      line = std::string_view(p, len);
      ++line_;
      return true;
    }
    if (a > kMaxLine) {
      throw InputError::at_line(src_.name(), line_ + 1,
                                "line longer than " + std::to_string(kMaxLine) + " bytes (binary data?)");
    }
    scanned = a;
    if (src_.fill_more() == a) {  // end of input
      if (a == 0) return false;
      std::size_t len = a;
      const char* q = src_.data();
      src_.consume(a);
      if (q[len - 1] == '\r') --len;
      line = std::string_view(q, len);
      ++line_;
      return true;
    }
  }
}

namespace {
inline bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }
inline bool ends_field(char c) { return is_blank(c) || c == ',' || c == ';' || c == '#'; }
}  // namespace

bool FieldSplitter::next(std::string_view& field) {
  while (p_ < end_ && is_blank(*p_)) ++p_;
  if (p_ == end_ || *p_ == '#') return false;
  if (!first_ && (*p_ == ',' || *p_ == ';')) {  // one separator between fields; a trailing one is fine
    ++p_;
    while (p_ < end_ && is_blank(*p_)) ++p_;
    if (p_ == end_ || *p_ == '#') return false;
  }
  first_ = false;
  const char* start = p_;
  // A field runs to a blank, a separator, a comment or the end of the line; a lone
  // separator where a field should start is a (bad) field of its own.
  if (*p_ == ',' || *p_ == ';') ++p_;
  while (p_ < end_ && !ends_field(*p_)) ++p_;
  field = std::string_view(start, p_ - start);
  return true;
}

bool parse_double(std::string_view field, double& v) {
  const char* p = field.data();
  const char* end = p + field.size();
  if (p < end && *p == '+') ++p;                                                // from_chars rejects a leading '+'
  if (p == end || *p == '+' || (*p == '-' && p != field.data())) return false;  // "+-1", "++1"
  const auto [ptr, ec] = std::from_chars(p, end, v);
  if (ptr != end || ptr == p) return false;
  if (ec == std::errc::result_out_of_range) {
    // from_chars leaves v unset on overflow: 1e999 is as unusable as inf, 1e-999 is 0.
    v = std::strtod(std::string(field).c_str(), nullptr);
  }
  return true;
}

int parse_numbers(std::string_view line, double* out, int cap, std::string_view& bad) {
  FieldSplitter fields(line);
  std::string_view f;
  int n = 0;
  while (fields.next(f)) {
    double v;
    if (!parse_double(f, v)) {
      bad = f;
      return -1;
    }
    if (n < cap) out[n] = v;
    ++n;
  }
  return n;
}

namespace {

// The header rule: a line is a header only if every field is a name, that is starts
// with a letter or '_' (after an optional double quote). "x y z", "X,Y,Z", "\"x\";\"y\""
// are headers; "1e5x 2 3", "--1 2 3", "x 2 z" are not (and are errors).
bool is_header_line(std::string_view line) {
  FieldSplitter fields(line);
  std::string_view f;
  int n = 0;
  while (fields.next(f)) {
    if (!f.empty() && f.front() == '"') f.remove_prefix(1);
    if (f.empty() || !(std::isalpha(static_cast<unsigned char>(f.front())) || f.front() == '_')) return false;
    ++n;
  }
  return n > 0;
}

class TextPointReader final : public PointReader {
 public:
  TextPointReader(std::unique_ptr<ByteSource> src, std::vector<std::uint64_t> columns)
      : src_(std::move(src)), lines_(*src_), columns_(std::move(columns)) {
    format_name_ = "text";
    source_name_ = src_->name();
    // A UTF-8 byte order mark before the first line is not part of it.
    src_->ensure(3);
    if (src_->available() >= 3 && std::memcmp(src_->data(), "\xEF\xBB\xBF", 3) == 0) src_->consume(3);
    if (!columns_.empty()) {
      format_name_ += " columns " + std::to_string(columns_[0]) + "," + std::to_string(columns_[1]) + "," +
                      std::to_string(columns_[2]);
    }
  }

  std::size_t read(double* xyz, std::size_t max_points) override {
    if (line_of_.size() < max_points) line_of_.resize(max_points);
    chunk_first_ = points_read_;
    std::size_t n = 0;
    std::string_view line;
    while (n < max_points && lines_.next(line)) {
      const std::uint64_t ln = lines_.line_number();
      double v[3];
      const int fields = columns_.empty() ? parse_xyz(line, ln, v) : parse_columns(line, ln, v);
      if (fields == 0) continue;  // blank, comment or header
      for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(v[c])) {
          throw InputError::at_line(source_name_, ln,
                                    std::string("non-finite coordinate (") + "xyz"[c] + " = " +
                                        (std::isnan(v[c]) ? "nan"
                                         : v[c] > 0       ? "inf"
                                                          : "-inf") +
                                        ")");
        }
        xyz[3 * n + c] = v[c];
      }
      line_of_[n] = ln;
      ++n;
    }
    points_read_ += n;
    if (n == 0 && points_read_ == 0) {
      throw InputError::at_line(source_name_, lines_.line_number() + 1, "no points in the input");
    }
    return n;
  }

  std::uint64_t bytes_read() const override { return src_->offset(); }
  std::optional<std::uint64_t> source_size() const override { return src_->size(); }

  std::string location(std::uint64_t index) const override {
    if (index >= chunk_first_ && index < points_read_) return "line " + std::to_string(line_of_[index - chunk_first_]);
    return "point " + std::to_string(index);
  }

 private:
  // Returns 0 for a line with no data (blank, comment, the header), else the number of
  // fields, and v = x, y, z. Throws on anything else.
  int skip_or_throw(std::string_view line, std::uint64_t ln, std::string_view bad) {
    if (!seen_data_ && is_header_line(line)) {  // the first line with fields may name the columns
      seen_data_ = true;
      return 0;
    }
    throw InputError::at_line(source_name_, ln, "not a number: '" + std::string(bad.substr(0, 40)) + "'");
  }

  int parse_xyz(std::string_view line, std::uint64_t ln, double* v) {
    std::string_view bad;
    const int fields = parse_numbers(line, v, 3, bad);
    if (fields == 0) return 0;
    if (fields < 0) return skip_or_throw(line, ln, bad);
    seen_data_ = true;
    if (fields != 3) {
      throw InputError::at_line(
          source_name_, ln,
          "expected 3 coordinates (x y z), found " + std::to_string(fields) + " fields (choose three with --columns)");
    }
    return fields;
  }

  // --columns: the chosen fields must be numbers; the others may be anything, but every
  // data line has as many fields as the first (a table, not ragged lines).
  int parse_columns(std::string_view line, std::uint64_t ln, double* v) {
    FieldSplitter split(line);
    std::string_view f;
    std::uint64_t k = 0;
    int found = 0;
    while (split.next(f)) {
      ++k;
      for (int c = 0; c < 3; ++c) {
        if (columns_[c] != k) continue;
        if (!parse_double(f, v[c])) return skip_or_throw(line, ln, f);
        ++found;
      }
    }
    if (k == 0) return 0;
    if (!seen_data_ && found < 3 && is_header_line(line)) {  // a short header line
      seen_data_ = true;
      return 0;
    }
    if (found < 3) {
      throw InputError::at_line(source_name_, ln,
                                "--columns " + std::to_string(columns_[0]) + "," + std::to_string(columns_[1]) + "," +
                                    std::to_string(columns_[2]) + ": the line has only " + std::to_string(k) +
                                    " fields");
    }
    if (seen_data_ && fields_ != 0 && k != fields_) {
      throw InputError::at_line(
          source_name_, ln,
          "expected " + std::to_string(fields_) + " fields like the first data line, found " + std::to_string(k));
    }
    seen_data_ = true;
    fields_ = k;
    return int(k);
  }

  std::unique_ptr<ByteSource> src_;
  LineSource lines_;
  std::vector<std::uint64_t> columns_;  // 1-based x, y, z columns; empty: exactly three fields
  std::uint64_t fields_ = 0;            // fields of the first data line (--columns)
  bool seen_data_ = false;
  std::uint64_t chunk_first_ = 0;
  std::vector<std::uint64_t> line_of_;  // line of each point of the last chunk
};

}  // namespace

std::unique_ptr<PointReader> open_text(std::unique_ptr<ByteSource> src, const PointReadOptions& options) {
  if (src->size() && *src->size() == 0) throw InputError::at_line(src->name(), 1, "empty file: no points");
  return std::make_unique<TextPointReader>(std::move(src), options.columns);
}

}  // namespace tetstream::io::detail
