// Several files as one input (the files of one snapshot, given one by one or by a glob):
// their points in file order, indexed across the files. Only one file is open at a
// time, so memory does not grow with the number of files; every header is read once up
// front, so a bad file is reported before any work and the count is known when every
// format states it.
#include "io/point_detail.hpp"

#include <algorithm>
#include <optional>
#include <vector>

namespace tetstream::io::detail {
namespace {

class ConcatPointReader final : public PointReader {
 public:
  ConcatPointReader(std::vector<std::string> paths, OpenOne open_one)
      : paths_(std::move(paths)), open_one_(std::move(open_one)) {
    source_name_ = paths_.front() + " (and " + std::to_string(paths_.size() - 1) + " more files)";
    std::uint64_t total = 0;
    bool known = true;
    std::string formats;
    float32_ = true;
    for (const auto& p : paths_) {
      const auto r = open_one_(p);  // checks the header; closed again at once
      float32_ = float32_ && r->float32_input();
      if (!r->count())
        known = false;
      else if (!checked_add(total, *r->count(), total))
        throw InputError(p + ": the files hold more than 2^64 points");
      if (formats.find(r->format_name()) == std::string::npos)
        formats += (formats.empty() ? "" : "; ") + r->format_name();
      sizes_.push_back(r->source_size().value_or(0));
      counts_.push_back(r->count());
    }
    if (known) count_ = total;
    if (known && total == 0) throw InputError(source_name_ + ": no points in any of the files");
    format_name_ = formats + ", " + std::to_string(paths_.size()) + " files";
  }

  std::size_t read(double* xyz, std::size_t max_points) override {
    while (next_ <= paths_.size()) {
      if (current_) {
        const std::size_t n = current_->read(xyz, max_points);
        if (n > 0) {
          points_read_ += n;
          return n;
        }
        bytes_done_ += current_->bytes_read();
        current_.reset();
      }
      if (next_ == paths_.size()) break;
      first_.push_back(points_read_);
      current_ = open_one_(paths_[next_++]);
    }
    next_ = paths_.size() + 1;
    if (points_read_ == 0) throw InputError(source_name_ + ": no points in any of the files");
    return 0;
  }

  // A whole file whose header gave its count (checked when this reader was made) is
  // passed without opening it; within a file, its own reader skips (seeking where it
  // can). A file with no points is opened as read() would (it is never skipped whole,
  // so whoever reaches it checks it to its end).
  std::uint64_t skip(std::uint64_t n) override {
    std::uint64_t done = 0;
    while (done < n) {
      if (current_) {
        const std::uint64_t k = current_->skip(n - done);
        done += k;
        points_read_ += k;
        if (done == n) break;
        bytes_done_ += current_->bytes_read();  // its end: on to the next file
        current_.reset();
        continue;
      }
      if (next_ >= paths_.size()) break;
      first_.push_back(points_read_);
      const std::optional<std::uint64_t> count = counts_[next_];
      if (count && *count > 0 && *count <= n - done) {
        done += *count;
        points_read_ += *count;
        bytes_done_ += sizes_[next_++];
        continue;
      }
      current_ = open_one_(paths_[next_++]);
    }
    return done;
  }

  std::uint64_t bytes_read() const override { return bytes_done_ + (current_ ? current_->bytes_read() : 0); }
  std::optional<std::uint64_t> source_size() const override {
    std::uint64_t total = 0;
    for (auto s : sizes_) total += s;
    return total;
  }

  std::string location(std::uint64_t index) const override {
    const std::size_t f = file_of(index);
    if (current_ && f + 1 == first_.size()) return current_->location(index - first_[f]);
    return "point " + std::to_string(index - (f < first_.size() ? first_[f] : 0)) + " of the file";
  }
  std::string source_of(std::uint64_t index) const override {
    const std::size_t f = file_of(index);
    return f < first_.size() ? paths_[f] : source_name_;
  }
  std::vector<std::pair<std::string, std::string>> details() const override {
    return {{"files", std::to_string(paths_.size())}};
  }

 private:
  std::size_t file_of(std::uint64_t index) const {  // the last file that starts at or before index
    const auto it = std::upper_bound(first_.begin(), first_.end(), index);
    return it == first_.begin() ? first_.size() : std::size_t(it - first_.begin()) - 1;
  }

  std::vector<std::string> paths_;
  OpenOne open_one_;
  std::vector<std::uint64_t> sizes_;
  std::vector<std::optional<std::uint64_t>> counts_;  // each file's, when its header gives it
  std::vector<std::uint64_t> first_;                  // index of the first point of each file opened so far
  std::unique_ptr<PointReader> current_;
  std::size_t next_ = 0;
  std::uint64_t bytes_done_ = 0;
};

}  // namespace

std::unique_ptr<PointReader> open_concat(std::vector<std::string> paths, OpenOne open_one) {
  return std::make_unique<ConcatPointReader>(std::move(paths), std::move(open_one));
}

}  // namespace tetstream::io::detail
