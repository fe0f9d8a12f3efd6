// lwsccd — a minimal PNG writer (8-bit RGB, zlib "stored" blocks: no compression, no dependency),
// for the pictures of render.hpp and the ray-tracing example.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace lwsccd::png {

inline std::uint32_t crc32(const unsigned char* data, std::size_t n, std::uint32_t crc = 0xffffffffu) {
  for (std::size_t i = 0; i < n; ++i) {
    crc ^= data[i];
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
  }
  return crc;
}

/// Writes width x height RGB pixels (row-major, 3 bytes each); returns false on an I/O error.
inline bool write_rgb(const std::string& path, int width, int height, const std::vector<unsigned char>& rgb) {
  std::vector<unsigned char> raw;  // each row: filter byte 0, then the pixels
  for (int y = 0; y < height; ++y) {
    raw.push_back(0);
    raw.insert(raw.end(), rgb.begin() + static_cast<std::ptrdiff_t>(y) * width * 3,
               rgb.begin() + static_cast<std::ptrdiff_t>(y + 1) * width * 3);
  }
  std::vector<unsigned char> z = {0x78, 0x01};  // zlib header, stored blocks of up to 65535 bytes
  std::uint32_t a = 1, b = 0;
  for (std::size_t pos = 0; pos < raw.size() || raw.empty();) {
    const std::size_t len = std::min<std::size_t>(65535, raw.size() - pos);
    const bool last = pos + len >= raw.size();
    z.push_back(last ? 1 : 0);
    z.push_back(len & 0xff), z.push_back(len >> 8), z.push_back(~len & 0xff), z.push_back((~len >> 8) & 0xff);
    z.insert(z.end(), raw.begin() + static_cast<std::ptrdiff_t>(pos), raw.begin() + static_cast<std::ptrdiff_t>(pos + len));
    pos += len;
    if (last) break;
  }
  for (unsigned char c : raw) a = (a + c) % 65521, b = (b + a) % 65521;
  const std::uint32_t adler = (b << 16) | a;
  for (int s = 24; s >= 0; s -= 8) z.push_back((adler >> s) & 0xff);
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return false;
  auto chunk = [&](const char* type, const std::vector<unsigned char>& data) {
    const std::uint32_t n = static_cast<std::uint32_t>(data.size());
    const unsigned char len[4] = {static_cast<unsigned char>(n >> 24), static_cast<unsigned char>(n >> 16),
                                  static_cast<unsigned char>(n >> 8), static_cast<unsigned char>(n)};
    std::fwrite(len, 1, 4, f);
    std::vector<unsigned char> body(type, type + 4);
    body.insert(body.end(), data.begin(), data.end());
    std::fwrite(body.data(), 1, body.size(), f);
    const std::uint32_t crc = crc32(body.data(), body.size()) ^ 0xffffffffu;
    const unsigned char c[4] = {static_cast<unsigned char>(crc >> 24), static_cast<unsigned char>(crc >> 16),
                                static_cast<unsigned char>(crc >> 8), static_cast<unsigned char>(crc)};
    std::fwrite(c, 1, 4, f);
  };
  const unsigned char signature[8] = {137, 80, 78, 71, 13, 10, 26, 10};
  std::fwrite(signature, 1, 8, f);
  std::vector<unsigned char> ihdr = {
      static_cast<unsigned char>(width >> 24),  static_cast<unsigned char>(width >> 16),
      static_cast<unsigned char>(width >> 8),   static_cast<unsigned char>(width),
      static_cast<unsigned char>(height >> 24), static_cast<unsigned char>(height >> 16),
      static_cast<unsigned char>(height >> 8),  static_cast<unsigned char>(height),
      8, 2, 0, 0, 0};  // 8-bit, truecolour, deflate, adaptive filter, no interlace
  chunk("IHDR", ihdr);
  chunk("IDAT", z);
  chunk("IEND", {});
  return std::fclose(f) == 0;
}

}  // namespace lwsccd::png
