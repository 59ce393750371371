// What the image file's pieces share (vision/image_file.h is the entry): the reader
// (image_file.cpp), the PNG decoder (image_file_png.cpp), the writer (image_file_write.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include <opencv2/core.hpp>

#include "vision/image_file.h"

namespace mcms::image_file_internal {

// A big-endian 32-bit word (PNG's lengths, TIFF's MM order).
uint32_t Be32(const unsigned char* p);
// 16-bit samples from one byte order to the other (PNG and PGM are big-endian).
void SwapBytes16(const unsigned char* src, unsigned char* dst, size_t samples);

// ReadImageFile, and ImageFileRows::Read when `rows` is given: then a PNG our decoder
// handles is inflated into *rows, and the image returned is rows->image(), not yet
// prepared.
cv::Mat ReadFrame(const std::filesystem::path& p, const ImageFileOptions& options, std::string* problem,
                  ImageFileReader* reader, ImageFileRows* rows);

}  // namespace mcms::image_file_internal
