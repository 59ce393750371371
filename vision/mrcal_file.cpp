#include "vision/mrcal_file.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
#include <numeric>
#include <optional>
#include <sstream>

#include <zlib.h>

#include "core/error.h"
#include "core/limits.h"
#include "core/io.h"
#include "vision/camera_model.h"

namespace mcms {
namespace mrcal_io {
namespace {

void Put16(std::string& s, uint32_t v) {
  s.push_back(static_cast<char>(v & 0xff));
  s.push_back(static_cast<char>((v >> 8) & 0xff));
}
void Put32(std::string& s, uint32_t v) {
  Put16(s, v & 0xffff);
  Put16(s, v >> 16);
}

std::string Deflate(const std::string& in) {
  z_stream zs{};
  if (deflateInit2(&zs, Z_DEFAULT_COMPRESSION, Z_DEFLATED, -15, 8, Z_DEFAULT_STRATEGY) != Z_OK)
    Throw("mrcal optimization_inputs: zlib deflateInit2 failed");
  std::string out(deflateBound(&zs, static_cast<uLong>(in.size())), '\0');
  zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(in.data()));
  zs.avail_in = static_cast<uInt>(in.size());
  zs.next_out = reinterpret_cast<Bytef*>(out.data());
  zs.avail_out = static_cast<uInt>(out.size());
  const int rc = deflate(&zs, Z_FINISH);
  const size_t n = zs.total_out;
  deflateEnd(&zs);
  if (rc != Z_STREAM_END) Throw("mrcal optimization_inputs: zlib deflate failed (", rc, ")");
  out.resize(n);
  return out;
}

}  // namespace

std::string B85Encode(const std::string& bytes) {
  static const char kAlphabet[] =
      "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz!#$%&()*+-;<=>?@^_`{|}~";
  std::string out;
  out.reserve((bytes.size() + 3) / 4 * 5);
  const size_t padding = (4 - bytes.size() % 4) % 4;
  for (size_t i = 0; i < bytes.size(); i += 4) {
    uint32_t w = 0;
    for (size_t k = 0; k < 4; ++k)
      w = (w << 8) | (i + k < bytes.size() ? static_cast<unsigned char>(bytes[i + k]) : 0u);
    char c[5];
    for (int k = 4; k >= 0; --k) c[k] = kAlphabet[w % 85], w /= 85;
    out.append(c, 5);
  }
  out.erase(out.size() - std::min(padding, out.size()));  // erase: never grows
  return out;
}

std::string Npy(const std::string& descr, const std::vector<size_t>& shape, const std::string& data) {
  std::ostringstream h;
  h << "{'descr': '" << descr << "', 'fortran_order': False, 'shape': (";
  for (size_t i = 0; i < shape.size(); ++i) h << (i ? ", " : "") << shape[i];
  if (shape.size() == 1) h << ",";
  h << "), }";
  std::string header = h.str();
  const size_t prefix = 10;  // magic (6), version (2), header length (2)
  header.append(63 - (prefix + header.size()) % 64, ' ');
  header.push_back('\n');
  std::string out("\x93NUMPY\x01\x00", 8);
  Put16(out, static_cast<uint32_t>(header.size()));
  out += header;
  out += data;
  return out;
}

std::string Zip(const std::vector<std::pair<std::string, std::string>>& members) {
  std::string out, central;
  constexpr uint32_t kDosDate = (0 << 9) | (1 << 5) | 1;  // 1980-01-01
  for (const auto& [name, data] : members) {
    const std::string packed = Deflate(data);
    const uint32_t crc =
        static_cast<uint32_t>(crc32(0L, reinterpret_cast<const Bytef*>(data.data()), static_cast<uInt>(data.size())));
    if (out.size() > 0xffffffffu || data.size() > 0xffffffffu) Throw("mrcal optimization_inputs: too large for zip");
    const uint32_t offset = static_cast<uint32_t>(out.size());
    Put32(out, 0x04034b50);
    Put16(out, 20);  // version needed
    Put16(out, 0);   // flags
    Put16(out, 8);   // deflate
    Put16(out, 0);   // time
    Put16(out, kDosDate);
    Put32(out, crc);
    Put32(out, static_cast<uint32_t>(packed.size()));
    Put32(out, static_cast<uint32_t>(data.size()));
    Put16(out, static_cast<uint32_t>(name.size()));
    Put16(out, 0);
    out += name;
    out += packed;
    Put32(central, 0x02014b50);
    Put16(central, 20);  // made by
    Put16(central, 20);  // needed
    Put16(central, 0);
    Put16(central, 8);
    Put16(central, 0);
    Put16(central, kDosDate);
    Put32(central, crc);
    Put32(central, static_cast<uint32_t>(packed.size()));
    Put32(central, static_cast<uint32_t>(data.size()));
    Put16(central, static_cast<uint32_t>(name.size()));
    Put16(central, 0);  // extra
    Put16(central, 0);  // comment
    Put16(central, 0);  // disk
    Put16(central, 0);  // internal attributes
    Put32(central, 0);  // external attributes
    Put32(central, offset);
    central += name;
  }
  const uint32_t central_offset = static_cast<uint32_t>(out.size());
  out += central;
  Put32(out, 0x06054b50);
  Put16(out, 0);
  Put16(out, 0);
  Put16(out, static_cast<uint32_t>(members.size()));
  Put16(out, static_cast<uint32_t>(members.size()));
  Put32(out, static_cast<uint32_t>(central.size()));
  Put32(out, central_offset);
  Put16(out, 0);
  return out;
}

}  // namespace mrcal_io
}  // namespace mcms


namespace mcms {
namespace mrcal_io {
namespace {

uint32_t Get16(const std::string& s, size_t at) {
  if (at + 2 > s.size()) Throw("zip archive truncated");
  return static_cast<uint32_t>(static_cast<unsigned char>(s[at])) |
         (static_cast<uint32_t>(static_cast<unsigned char>(s[at + 1])) << 8);
}
uint32_t Get32(const std::string& s, size_t at) { return Get16(s, at) | (Get16(s, at + 2) << 16); }
uint64_t Get64(const std::string& s, size_t at) {
  return static_cast<uint64_t>(Get32(s, at)) | (static_cast<uint64_t>(Get32(s, at + 4)) << 32);
}

std::string Inflate(const std::string& in, size_t expected) {
  z_stream zs{};
  if (inflateInit2(&zs, -15) != Z_OK) Throw("zlib inflateInit2 failed");
  std::string out(expected, '\0');
  zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(in.data()));
  zs.avail_in = static_cast<uInt>(in.size());
  zs.next_out = reinterpret_cast<Bytef*>(out.data());
  zs.avail_out = static_cast<uInt>(out.size());
  const int rc = inflate(&zs, Z_FINISH);
  const size_t n = zs.total_out;
  inflateEnd(&zs);
  if (rc != Z_STREAM_END || n != expected) Throw("zip member does not inflate to its stated size");
  return out;
}

}  // namespace

std::string B85Decode(const std::string& text) {
  static const char kAlphabet[] =
      "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz!#$%&()*+-;<=>?@^_`{|}~";
  int value[256];
  std::fill(std::begin(value), std::end(value), -1);
  for (int i = 0; i < 85; ++i) value[static_cast<unsigned char>(kAlphabet[i])] = i;
  std::string out;
  out.reserve(text.size() / 5 * 4 + 4);
  const size_t padding = (5 - text.size() % 5) % 5;
  for (size_t i = 0; i < text.size(); i += 5) {
    uint64_t w = 0;
    for (size_t k = 0; k < 5; ++k) {
      int v = 84;  // padding with '~'
      if (i + k < text.size()) {
        v = value[static_cast<unsigned char>(text[i + k])];
        if (v < 0) Throw("base85: character '", text[i + k], "' at ", i + k, " is not in the alphabet");
      }
      w = w * 85 + static_cast<uint64_t>(v);
    }
    if (w > 0xffffffffull) Throw("base85: group at ", i, " overflows");
    for (int k = 3; k >= 0; --k) out.push_back(static_cast<char>((w >> (8 * k)) & 0xff));
  }
  out.erase(out.size() - std::min(padding, out.size()));  // erase: never grows
  return out;
}

std::map<std::string, std::string> Unzip(const std::string& zip) {
  // End of central directory: the last "PK\5\6".
  if (zip.size() < 22) Throw("zip archive too short");
  size_t eocd = std::string::npos;
  for (size_t i = zip.size() - 22 + 1; i-- > 0;)
    if (Get32(zip, i) == 0x06054b50u) {
      eocd = i;
      break;
    }
  if (eocd == std::string::npos) Throw("zip archive has no end of central directory");
  uint64_t entries = Get16(zip, eocd + 10), cd = Get32(zip, eocd + 16);
  if (cd == 0xffffffffu || entries == 0xffffu) {  // zip64: the locator sits before the EOCD
    if (eocd < 20 || Get32(zip, eocd - 20) != 0x07064b50u) Throw("zip64 archive without locator");
    const uint64_t e64 = Get64(zip, eocd - 20 + 8);
    if (e64 + 56 > zip.size() || Get32(zip, e64) != 0x06064b50u) Throw("zip64 end of central directory missing");
    entries = Get64(zip, e64 + 32);
    cd = Get64(zip, e64 + 48);
  }
  std::map<std::string, std::string> members;
  size_t at = cd, inflated = 0;
  for (uint64_t e = 0; e < entries; ++e) {
    if (Get32(zip, at) != 0x02014b50u) Throw("zip central directory entry ", e, " is corrupt");
    const uint32_t method = Get16(zip, at + 10);
    uint64_t csize = Get32(zip, at + 20), usize = Get32(zip, at + 24);
    const uint32_t name_len = Get16(zip, at + 28), extra_len = Get16(zip, at + 30), comment_len = Get16(zip, at + 32);
    uint64_t local = Get32(zip, at + 42);
    if (at + 46 + name_len > zip.size()) Throw("zip archive truncated");
    const std::string name = zip.substr(at + 46, name_len);
    for (size_t x = at + 46 + name_len; x + 4 <= at + 46 + name_len + extra_len;) {
      const uint32_t id = Get16(zip, x), len = Get16(zip, x + 2);
      if (id == 0x0001) {
        size_t y = x + 4;
        if (usize == 0xffffffffu) usize = Get64(zip, y), y += 8;
        if (csize == 0xffffffffu) csize = Get64(zip, y), y += 8;
        if (local == 0xffffffffu) local = Get64(zip, y), y += 8;
      }
      x += 4 + len;
    }
    if (Get32(zip, local) != 0x04034b50u) Throw("zip member ", name, ": bad local header");
    const size_t data = local + 30 + Get16(zip, local + 26) + Get16(zip, local + 28);
    if (data + csize > zip.size()) Throw("zip member ", name, " truncated");
    // Bounded before anything is allocated: a deflate bomb states gigabytes.
    if (usize > kMaxInflatedBytes - std::min<uint64_t>(inflated, kMaxInflatedBytes))
      Throw("zip member ", name, " states ", usize, " bytes inflated (", inflated, " before it), beyond the ",
            kMaxInflatedBytes >> 20, " MB an mrcal calibration's arrays may take (core/limits.h): a corrupt or hostile archive");
    inflated += usize;
    const std::string raw = zip.substr(data, csize);
    if (method == 0) members[name] = raw;
    else if (method == 8) members[name] = Inflate(raw, usize);
    else Throw("zip member ", name, ": compression method ", method, " not supported");
    at += 46 + name_len + extra_len + comment_len;
  }
  return members;
}

NpyArray ParseNpy(const std::string& npy) {
  if (npy.size() < 10 || npy.compare(0, 6, "\x93NUMPY") != 0) Throw("not a .npy array");
  const int major = static_cast<unsigned char>(npy[6]);
  size_t header_len = 0, start = 0;
  if (major == 1) header_len = Get16(npy, 8), start = 10;
  else header_len = Get32(npy, 8), start = 12;
  if (start + header_len > npy.size()) Throw(".npy header truncated");
  const std::string h = npy.substr(start, header_len);
  NpyArray a;
  const auto quoted = [&](const std::string& key) {
    const size_t k = h.find("'" + key + "'");
    if (k == std::string::npos) Throw(".npy header has no ", key);
    const size_t q0 = h.find('\'', h.find(':', k) + 1), q1 = h.find('\'', q0 + 1);
    if (q0 == std::string::npos || q1 == std::string::npos) Throw(".npy header: bad ", key);
    return h.substr(q0 + 1, q1 - q0 - 1);
  };
  a.descr = quoted("descr");
  const size_t fo = h.find("'fortran_order'");
  if (fo != std::string::npos && h.compare(h.find(':', fo) + 1, 5, " True") == 0)
    Throw(".npy array in Fortran order is not supported");
  const size_t s = h.find("'shape'");
  if (s == std::string::npos) Throw(".npy header has no shape");
  const size_t p0 = h.find('(', s), p1 = h.find(')', p0);
  if (p0 == std::string::npos || p1 == std::string::npos) Throw(".npy header: bad shape");
  std::stringstream ss(h.substr(p0 + 1, p1 - p0 - 1));
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item.find_first_not_of(' ') == std::string::npos) continue;
    a.shape.push_back(static_cast<size_t>(std::stoull(item)));
  }
  a.data = npy.substr(start + header_len);
  return a;
}

}  // namespace mrcal_io

namespace {

using mrcal_io::NpyArray;

uint32_t Get32Le(const std::string& s, size_t at) {
  uint32_t v = 0;
  for (int k = 3; k >= 0; --k) v = (v << 8) | static_cast<unsigned char>(s[at + static_cast<size_t>(k)]);
  return v;
}

size_t Count(const NpyArray& a) {
  size_t n = 1;
  for (size_t d : a.shape) n *= d;
  return n;
}

template <typename T>
std::vector<T> Values(const NpyArray& a, const std::string& descr, const std::string& what) {
  if (a.descr != descr) Throw(what, " has type ", a.descr, ", expected ", descr);
  const size_t n = Count(a);
  if (a.data.size() < n * sizeof(T)) Throw(what, " is truncated");
  std::vector<T> v(n);
  if (n > 0) std::memcpy(v.data(), a.data.data(), n * sizeof(T));
  return v;
}

std::vector<double> Doubles(const NpyArray& a, const std::string& what) {
  std::vector<double> v = Values<double>(a, "<f8", what);
  for (size_t i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i])) Throw(what, " has a value that is not finite (element ", i, ")");
  return v;
}

}  // namespace

MrcalOptimizationInputsData ReadMrcalOptimizationInputs(const std::filesystem::path& path) {
  const std::string where = "mrcal model " + path.string() + ": ";
  std::string text;
  try {
    text = ReadTextFile(path);
  } catch (const std::exception& e) {
    Throw(where, e.what());
  }
  // Not a .cameramodel at all, or its own lens model or intrinsics broken: named before
  // the optimization_inputs are looked for.
  CameraModel::CheckCameramodelText(text, path);
  MrcalOptimizationInputsData d;
  try {
    // A model cut short (a copy interrupted, a disk full): its dict never closes.
    const size_t last = text.find_last_not_of(" \t\r\n");
    if (last == std::string::npos || text[last] != '}')
      Throw("the file ends before the model's closing '}' (", text.size(), " bytes): cut short? write it again");
    const size_t key = text.find("'optimization_inputs'");
    if (key == std::string::npos)
      Throw("no 'optimization_inputs' (the model was written without its calibration problem; the lens audit needs "
            "the chessboard observations mrcal stores there)");
    const size_t b = text.find("b'", key);
    const size_t e = b == std::string::npos ? b : text.find('\'', b + 2);
    if (e == std::string::npos) Throw("'optimization_inputs' is not a bytes literal b'...'");
    const size_t ic = text.find("'icam_intrinsics'");
    if (ic != std::string::npos) {
      const size_t colon = text.find(':', ic);
      if (colon == std::string::npos) Throw("'icam_intrinsics' has no value");
      const long v = std::strtol(text.c_str() + colon + 1, nullptr, 10);
      if (v < 0 || v > 1000000) Throw("'icam_intrinsics' is ", v, ", expected a camera index");
      d.icam_intrinsics = static_cast<int>(v);
    }
    std::map<std::string, std::string> members;
    try {
      members = mrcal_io::Unzip(mrcal_io::B85Decode(text.substr(b + 2, e - b - 2)));
    } catch (const std::exception& ex) {
      Throw("'optimization_inputs' do not decode (base85 of a numpy .npz): ", ex.what());
    }
    const auto array = [&](const std::string& name) -> std::optional<NpyArray> {
      const auto it = members.find(name + ".npy");
      if (it == members.end()) return std::nullopt;
      NpyArray a = mrcal_io::ParseNpy(it->second);
      // None: a pickled object, or the empty string this project's writer stores for it.
      if (a.descr == "|O" || (name != "lensmodel" && a.descr.compare(0, 2, "<U") == 0 &&
                              a.data.find_first_not_of('\0') == std::string::npos))
        return std::nullopt;
      return a;
    };
    const auto need = [&](const std::string& name) {
      auto a = array(name);
      if (!a) Throw("optimization_inputs have no ", name);
      return *a;
    };
    const auto obs = array("observations_board");
    if (!obs || Count(*obs) == 0)
      Throw("optimization_inputs hold no chessboard observations (observations_board is ",
            obs ? "empty" : "missing", "); the lens audit needs a chessboard calibration");
    if (obs->shape.size() != 4 || obs->shape[3] != 3)
      Throw("observations_board has shape of rank ", obs->shape.size(), ", expected (N, H, W, 3)");
    d.board_height_n = static_cast<int>(obs->shape[1]);
    d.board_width_n = static_cast<int>(obs->shape[2]);
    d.observations_board = Doubles(*obs, "observations_board");
    const size_t nobs = obs->shape[0];
    // The lens model: a 0-d numpy unicode string (UTF-32LE).
    const NpyArray lm = need("lensmodel");
    if (lm.descr.size() < 3 || lm.descr.compare(0, 2, "<U") != 0) Throw("lensmodel has type ", lm.descr);
    for (size_t i = 0; i + 4 <= lm.data.size(); i += 4) {
      const uint32_t c = Get32Le(lm.data, i);
      if (c == 0) break;
      d.lensmodel.push_back(static_cast<char>(c));
    }
    const NpyArray intr = need("intrinsics");
    if (intr.shape.size() != 2 || intr.shape[0] == 0) Throw("intrinsics: expected shape (Ncameras, Nparams)");
    const std::vector<double> iv = Doubles(intr, "intrinsics");
    for (size_t c = 0; c < intr.shape[0]; ++c)
      d.intrinsics.emplace_back(iv.begin() + static_cast<long>(c * intr.shape[1]),
                                iv.begin() + static_cast<long>((c + 1) * intr.shape[1]));
    const NpyArray sizes = need("imagersizes");
    const std::vector<int32_t> sv = Values<int32_t>(sizes, "<i4", "imagersizes");
    for (size_t c = 0; c + 1 < sv.size(); c += 2) {
      if (sv[c] <= 0 || sv[c + 1] <= 0 || sv[c] > 100000 || sv[c + 1] > 100000)
        Throw("imagersizes: camera ", c / 2, " is ", sv[c], "x", sv[c + 1], ", expected positive sizes up to 100000");
      d.imagersizes.push_back({sv[c], sv[c + 1]});
    }
    const auto rt = [&](const std::string& name) {
      std::vector<std::array<double, 6>> out;
      const auto a = array(name);
      if (!a) return out;
      const std::vector<double> v = Doubles(*a, name);
      if (v.size() % 6 != 0) Throw(name, ": expected shape (N, 6)");
      for (size_t i = 0; i < v.size(); i += 6) out.push_back({v[i], v[i + 1], v[i + 2], v[i + 3], v[i + 4], v[i + 5]});
      return out;
    };
    d.extrinsics_rt_fromref = rt("extrinsics_rt_fromref");
    d.frames_rt_toref = rt("frames_rt_toref");
    const std::vector<int32_t> idx =
        Values<int32_t>(need("indices_frame_camintrinsics_camextrinsics"), "<i4", "indices_frame_camintrinsics_camextrinsics");
    if (idx.size() != 3 * nobs)
      Throw("indices_frame_camintrinsics_camextrinsics has ", idx.size() / 3, " rows for ", nobs, " observations");
    for (size_t i = 0; i < nobs; ++i) {
      const std::array<int, 3> r{idx[3 * i], idx[3 * i + 1], idx[3 * i + 2]};
      if (r[0] < 0 || r[0] >= static_cast<int>(d.frames_rt_toref.size()) || r[1] < 0 ||
          r[1] >= static_cast<int>(d.intrinsics.size()) || r[2] < -1 ||
          r[2] >= static_cast<int>(d.extrinsics_rt_fromref.size()))
        Throw("board observation ", i, " refers to frame ", r[0], ", camera ", r[1], ", extrinsics ", r[2],
              " that do not exist");
      d.indices_frame_camintrinsics_camextrinsics.push_back(r);
    }
    if (d.imagersizes.size() != d.intrinsics.size()) Throw("imagersizes and intrinsics disagree on the camera count");
    const NpyArray sp = need("calibration_object_spacing");
    d.spacing_m = Doubles(sp, "calibration_object_spacing").at(0);
    if (!(d.spacing_m > 0)) Throw("calibration_object_spacing is ", d.spacing_m, ", expected > 0");
    if (const auto w = array("calobject_warp")) {
      const std::vector<double> v = Doubles(*w, "calobject_warp");
      if (v.size() == 2) d.has_calobject_warp = true, d.calobject_warp = {v[0], v[1]};
    }
    if (d.icam_intrinsics < 0 || d.icam_intrinsics >= static_cast<int>(d.intrinsics.size()))
      Throw("icam_intrinsics ", d.icam_intrinsics, " is not a camera of the problem");
  } catch (const InputError& ex) {
    Throw(where, ex.what());
  } catch (const std::exception& ex) {
    Throw(where, "optimization_inputs are malformed: ", ex.what());
  }
  return d;
}

}  // namespace mcms
