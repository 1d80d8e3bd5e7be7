#include "io/tet_periodic.hpp"

#include "core/error.hpp"
#include "io/tet_container.hpp"
#include "io/tet_reader.hpp"

#include <cmath>
#include <cstring>
#include <stdexcept>
#include <zstd.h>

namespace tetstream::io {

namespace {
void put64(std::vector<std::uint8_t>& b, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) b.push_back(std::uint8_t(v >> (8 * i)));
}
std::uint64_t get64(const std::uint8_t* p) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= std::uint64_t(p[i]) << (8 * i);
  return v;
}
constexpr std::size_t kEntryBytes = 16;  // u64 offset, u32 bytes, u32 tets
}  // namespace

std::vector<std::uint8_t> serialize_periodic_box(const PeriodicBox& box) {
  std::vector<std::uint8_t> b;
  for (double l : box.period) {
    std::uint64_t bits;
    std::memcpy(&bits, &l, 8);
    put64(b, bits);
  }
  b.push_back(std::uint8_t(box.sort_axis));
  b.resize(kPeriodicBoxBytes, 0);
  return b;
}

PeriodicBox parse_periodic_box(std::span<const std::uint8_t> payload, const std::string& file) {
  if (payload.size() < kPeriodicBoxBytes) throw InputError(file + ": PBOX section: shorter than 32 bytes");
  PeriodicBox box;
  for (int k = 0; k < 3; ++k) {
    const std::uint64_t bits = get64(payload.data() + 8 * k);
    std::memcpy(&box.period[k], &bits, 8);
    if (!std::isfinite(box.period[k]) || box.period[k] <= 0) {
      throw InputError(file + ": PBOX section: period " + std::to_string(k) + " is not a positive number");
    }
  }
  box.sort_axis = payload[24];
  if (box.sort_axis > 2) throw InputError(file + ": PBOX section: sort axis " + std::to_string(box.sort_axis));
  return box;
}

std::span<const std::uint8_t> PeriodicOffsetsWriter::add_frame(std::span<const std::uint16_t> codes) {
  std::vector<std::uint8_t> raw(2 * codes.size());
  for (std::size_t i = 0; i < codes.size(); ++i) {
    raw[2 * i] = std::uint8_t(codes[i]);
    raw[2 * i + 1] = std::uint8_t(codes[i] >> 8);
  }
  std::vector<std::uint8_t> z(ZSTD_compressBound(raw.size()));
  const std::size_t n = ZSTD_compress(z.data(), z.size(), raw.data(), raw.size(), 3);
  if (ZSTD_isError(n)) throw std::runtime_error(std::string("zstd: ") + ZSTD_getErrorName(n));
  add_compressed(std::span<const std::uint8_t>(z.data(), n), std::uint32_t(codes.size()));
  return std::span<const std::uint8_t>(data_).subspan(data_.size() - n);
}

void PeriodicOffsetsWriter::add_compressed(std::span<const std::uint8_t> bytes, std::uint32_t tets) {
  entries_.push_back({data_.size(), std::uint32_t(bytes.size()), tets});
  data_.insert(data_.end(), bytes.begin(), bytes.end());
}

std::vector<std::uint8_t> PeriodicOffsetsWriter::payload() const {
  std::vector<std::uint8_t> b;
  put64(b, entries_.size());
  const std::uint64_t base = 8 + kEntryBytes * entries_.size();
  for (const Entry& e : entries_) {
    put64(b, base + e.offset);
    put64(b, std::uint64_t(e.bytes) | std::uint64_t(e.tets) << 32);
  }
  b.insert(b.end(), data_.begin(), data_.end());
  return b;
}

PeriodicOffsetsReader::PeriodicOffsetsReader(const TetReader& reader) : reader_(reader) {
  payload_ = reader.section(kTagPeriodicOffsets);
  if (payload_.size() < 8 || get64(payload_.data()) != reader.frame_count() ||
      (payload_.size() - 8) / kEntryBytes < reader.frame_count()) {
    throw InputError(reader.path() + ": POFS section: missing, or not one entry a frame");
  }
}

void PeriodicOffsetsReader::read(std::uint64_t k, std::vector<std::uint16_t>& codes) const {
  const std::uint8_t* e = payload_.data() + 8 + kEntryBytes * k;
  const std::uint64_t at = get64(e), sizes = get64(e + 8);
  const std::uint64_t bytes = sizes & 0xffffffffu, tets = sizes >> 32;
  const std::string where = reader_.path() + ": POFS section: frame " + std::to_string(k) + ": ";
  if (tets != reader_.frames()[k].tet_count) throw InputError(where + "tet count differs from the frame's");
  if (at > payload_.size() || bytes > payload_.size() - at) throw InputError(where + "lies outside the section");
  std::vector<std::uint8_t> raw(2 * tets);
  const std::size_t n = ZSTD_decompress(raw.data(), raw.size(), payload_.data() + at, bytes);
  if (ZSTD_isError(n) || n != raw.size()) throw InputError(where + "damaged offsets");
  codes.resize(tets);
  for (std::size_t i = 0; i < tets; ++i) {
    codes[i] = std::uint16_t(raw[2 * i] | raw[2 * i + 1] << 8);
    if (codes[i] >= 27 * 27 * 27) throw InputError(where + "offset code out of range");
  }
}

}  // namespace tetstream::io
