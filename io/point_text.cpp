// Text points: one point per line, "x y z" or "x,y,z" (blanks, commas or semicolons),
// '#' comments, blank lines, and an optional header line (a first data line whose
// first field is not a number). Numbers are parsed with std::from_chars.
#include "io/point_detail.hpp"

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
}  // namespace

int parse_numbers(std::string_view line, double* out, int cap, std::string_view& bad) {
  const char* p = line.data();
  const char* end = p + line.size();
  int n = 0;
  for (;;) {
    while (p < end && is_blank(*p)) ++p;
    if (p == end || *p == '#') return n;
    if (n > 0 && (*p == ',' || *p == ';')) {  // one separator between fields; a trailing one is fine
      ++p;
      while (p < end && is_blank(*p)) ++p;
      if (p == end || *p == '#') return n;
    }
    const char* start = p;
    if (*p == '+') ++p;  // from_chars rejects a leading '+'
    double v;
    const auto [ptr, ec] = std::from_chars(p, end, v);
    // A field ends at a blank, a separator, a comment or the end of the line.
    if (ptr == p || (ptr < end && !is_blank(*ptr) && *ptr != ',' && *ptr != ';' && *ptr != '#')) {
      const char* stop = start;
      while (stop < end && !is_blank(*stop) && *stop != ',' && *stop != ';') ++stop;
      bad = std::string_view(start, stop - start);
      return -1;
    }
    if (ec == std::errc::result_out_of_range) {
      // from_chars leaves v unset on overflow: 1e999 is as unusable as inf, 1e-999 is 0.
      bad = std::string_view(start, ptr - start);
      v = std::strtod(std::string(bad).c_str(), nullptr);
    }
    if (n < cap) out[n] = v;
    ++n;
    p = ptr;
  }
}

namespace {

class TextPointReader final : public PointReader {
 public:
  explicit TextPointReader(std::unique_ptr<ByteSource> src) : src_(std::move(src)), lines_(*src_) {
    format_name_ = "text";
    source_name_ = src_->name();
  }

  std::size_t read(double* xyz, std::size_t max_points) override {
    if (line_of_.size() < max_points) line_of_.resize(max_points);
    chunk_first_ = points_read_;
    std::size_t n = 0;
    std::string_view line, bad;
    while (n < max_points && lines_.next(line)) {
      double v[3];
      const int fields = parse_numbers(line, v, 3, bad);
      const std::uint64_t ln = lines_.line_number();
      if (fields == 0) continue;  // blank or comment
      if (fields < 0) {
        if (!seen_data_ && !bad.empty() && bad.data() == first_field(line)) {
          seen_data_ = true;  // a header line: names, not numbers
          continue;
        }
        throw InputError::at_line(source_name_, ln, "not a number: '" + std::string(bad.substr(0, 40)) + "'");
      }
      seen_data_ = true;
      if (fields != 3) {
        throw InputError::at_line(source_name_, ln,
                                  "expected 3 coordinates (x y z), found " + std::to_string(fields));
      }
      for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(v[c])) {
          throw InputError::at_line(source_name_, ln,
                                    std::string("non-finite coordinate (") + "xyz"[c] + " = " +
                                        (std::isnan(v[c]) ? "nan" : v[c] > 0 ? "inf" : "-inf") + ")");
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
  static const char* first_field(std::string_view line) {
    const char* p = line.data();
    while (p < line.data() + line.size() && is_blank(*p)) ++p;
    return p;
  }

  std::unique_ptr<ByteSource> src_;
  LineSource lines_;
  bool seen_data_ = false;
  std::uint64_t chunk_first_ = 0;
  std::vector<std::uint64_t> line_of_;  // line of each point of the last chunk
};

}  // namespace

std::unique_ptr<PointReader> open_text(std::unique_ptr<ByteSource> src) {
  if (src->size() && *src->size() == 0) throw InputError::at_line(src->name(), 1, "empty file: no points");
  return std::make_unique<TextPointReader>(std::move(src));
}

}  // namespace tetstream::io::detail
