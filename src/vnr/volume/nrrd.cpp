// NRRD headers (.nrrd with attached data, .nhdr with a detached "data file"); raw or gzip encoding.
// Only what a scalar volume needs is interpreted; other fields are ignored.
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <sstream>
#include "vnr/error.h"
#include "vnr/fileio.h"
#include "vnr/volume/formats.h"

namespace vnr::detail {
namespace {

struct Header {
  std::map<std::string, std::string> fields;  // lower-case field name -> value
  uint64_t data_start = 0;                     // first byte after the header (attached data)
};

std::string trim(const std::string& s) {
  size_t b = s.find_first_not_of(" \t\r"), e = s.find_last_not_of(" \t\r");
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

// Reads the header only: a .nrrd can be gigabytes, its header ends at the first empty line.
Header read_header(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) fail("cannot open '{}': {}", path, std::strerror(errno));
  std::string text;
  char buf[1 << 14];
  size_t end = std::string::npos, skip = 0;
  while (end == std::string::npos) {
    size_t n = std::fread(buf, 1, sizeof buf, f);
    if (n == 0) break;
    size_t from = text.size() > 3 ? text.size() - 3 : 0;
    text.append(buf, n);
    size_t a = text.find("\n\n", from), b = text.find("\n\r\n", from);
    if (a != std::string::npos && (b == std::string::npos || a < b)) end = a, skip = 2;
    else if (b != std::string::npos) end = b, skip = 3;
    if (end == std::string::npos && text.size() > (16u << 20)) {
      std::fclose(f);
      fail("'{}': malformed NRRD header (no empty line ending the header within 16 MiB)", path);
    }
  }
  std::fclose(f);
  if (text.compare(0, 7, "NRRD000") != 0) fail("'{}': not a NRRD file (does not start with NRRD000x)", path);

  Header h;
  h.data_start = end == std::string::npos ? text.size() : end + skip;
  std::istringstream in(text.substr(0, end == std::string::npos ? text.size() : end));
  std::string line;
  std::getline(in, line);  // magic
  int lineno = 1;
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    size_t kv = line.find(":=");
    size_t c = line.find(": ");
    if (kv != std::string::npos && (c == std::string::npos || kv < c)) continue;  // key/value pair
    if (c == std::string::npos) {
      if (!line.empty() && line.back() == ':') c = line.size() - 1;  // field with an empty value
      else fail("'{}': malformed NRRD header line {}: '{}'", path, lineno, line);
    }
    h.fields[to_lower(trim(line.substr(0, c)))] = trim(line.substr(c + 1));
  }
  return h;
}

std::vector<std::string> words(const std::string& s) {
  std::istringstream in(s);
  std::vector<std::string> out;
  for (std::string w; in >> w;) out.push_back(w);
  return out;
}

int64_t parse_int(const std::string& s, const std::string& path, const char* field) {
  char* e = nullptr;
  errno = 0;
  long long v = std::strtoll(s.c_str(), &e, 10);
  if (s.empty() || *e != 0 || errno) fail("'{}': malformed NRRD header: {} has '{}', expected an integer", path, field, s);
  return v;
}

// "(1, 0,0) none (0,1,0)" -> {"(1,0,0)", "none", "(0,1,0)"}: vectors may contain spaces.
std::vector<std::string> direction_words(const std::string& s) {
  std::vector<std::string> out;
  for (size_t i = 0; i < s.size();) {
    if (s[i] == ' ' || s[i] == '\t') {
      ++i;
    } else if (s[i] == '(') {
      size_t e = s.find(')', i);
      e = e == std::string::npos ? s.size() : e + 1;
      std::string v;
      for (size_t k = i; k < e; ++k)
        if (s[k] != ' ' && s[k] != '\t') v += s[k];
      out.push_back(v);
      i = e;
    } else {
      size_t e = s.find_first_of(" \t", i);
      e = e == std::string::npos ? s.size() : e;
      out.push_back(s.substr(i, e - i));
      i = e;
    }
  }
  return out;
}

// "(a,b,c)" -> its length; "none" -> nan
double direction_length(const std::string& s, const std::string& path) {
  if (s == "none") return NAN;
  if (s.size() < 2 || s.front() != '(' || s.back() != ')')
    fail("'{}': malformed NRRD header: space directions entry '{}'", path, s);
  std::string inner = s.substr(1, s.size() - 2);
  double sum = 0;
  std::istringstream in(inner);
  for (std::string c; std::getline(in, c, ',');) {
    char* e = nullptr;
    double v = std::strtod(c.c_str(), &e);
    if (e == c.c_str()) fail("'{}': malformed NRRD header: space directions entry '{}'", path, s);
    sum += v * v;
  }
  return std::sqrt(sum);
}

// Kinds that describe a per-voxel component axis rather than a sampled domain.
bool is_component_kind(const std::string& k) {
  std::string l = to_lower(k);
  return !(l == "domain" || l == "space" || l == "time" || l == "none" || l == "???");
}

// A header's fields, failing with the file's name when a required one is missing.
struct Fields {
  const Header& h;
  const std::string& path;
  const std::string& operator()(const char* name) const {
    auto it = h.fields.find(name);
    if (it == h.fields.end()) fail("'{}': malformed NRRD header: missing '{}' field", path, name);
    return it->second;
  }
  bool has(const char* name) const { return h.fields.count(name) > 0; }
};

// dims, spacing and time steps from "dimension", "sizes", "kinds" and "spacings" / "space directions".
void read_axes(const Fields& field, const std::string& path, VolumeDesc& d) {
  auto has = [&](const char* name) { return field.has(name); };
  int dim = int(parse_int(field("dimension"), path, "dimension"));
  std::vector<std::string> size_words = words(field("sizes"));
  if (int(size_words.size()) != dim)
    fail("'{}': malformed NRRD header: dimension {} but {} sizes", path, dim, size_words.size());
  if (dim != 3 && dim != 4)
    fail("'{}': NRRD dimension {} is not supported (3, or 4 with time as the last axis)", path, dim);
  std::vector<int64_t> sizes;
  for (auto& w : size_words) sizes.push_back(parse_int(w, path, "sizes"));

  std::vector<std::string> kinds = has("kinds") ? words(field("kinds")) : std::vector<std::string>{};
  std::vector<double> spacing(dim, NAN);
  if (has("spacings")) {
    auto w = words(field("spacings"));
    for (int a = 0; a < dim && a < int(w.size()); ++a) spacing[a] = std::strtod(w[a].c_str(), nullptr);
  } else if (has("space directions")) {
    auto w = direction_words(field("space directions"));
    for (int a = 0; a < dim && a < int(w.size()); ++a) spacing[a] = direction_length(w[a], path);
  }

  // Map the axes onto x, y, z (+ time). Axis 0 is the fastest.
  std::vector<int> spatial;  // axis indices used for x, y, z
  int time_axis = -1;
  if (dim == 3) {
    spatial = {0, 1, 2};
  } else if (sizes[0] == 1) {  // a degenerate component axis in front
    spatial = {1, 2, 3};
  } else if (!kinds.empty() && kinds.size() == 4 && (is_component_kind(kinds[0]) || to_lower(kinds[0]) == "time")) {
    fail("'{}': 4-D NRRD whose first (fastest) axis is '{}' with {} values per voxel is not supported; vnr reads "
         "scalar volumes, with an optional time axis last",
         path, kinds[0], sizes[0]);
  } else {
    spatial = {0, 1, 2};
    time_axis = 3;
  }
  for (int a = 0; a < 3; ++a) {
    d.dims[a] = sizes[spatial[a]];
  }
  float sp[3];
  for (int a = 0; a < 3; ++a) {
    double v = spacing[spatial[a]];
    sp[a] = std::isfinite(v) && v > 0 ? float(v) : 1.f;
  }
  d.spacing = {sp[0], sp[1], sp[2]};
  if (time_axis >= 0) {
    if (sizes[time_axis] <= 0 || sizes[time_axis] > (1 << 30))
      fail("'{}': NRRD time axis size {} is invalid", path, sizes[time_axis]);
    d.n_timesteps = int(sizes[time_axis]);
  }
}

// Encoding, and where the data is: after the header, or in a detached file relative to the header,
// after "line skip" lines and "byte skip" bytes (-1: at the end of the file).
void locate_data(const Fields& field, const std::string& path, Source& s) {
  auto has = [&](const char* name) { return field.has(name); };
  VolumeDesc& d = s.desc;
  std::string enc = to_lower(field("encoding"));
  if (enc == "raw") d.encoding = "raw";
  else if (enc == "gzip" || enc == "gz") d.encoding = "gzip";
  else fail("'{}': NRRD encoding '{}' is not supported (supported: raw, gzip)", path, enc);

  uint64_t start = field.h.data_start;
  d.path = path;
  std::string data_file = has("data file") ? field("data file") : (has("datafile") ? field("datafile") : "");
  if (!data_file.empty()) {
    if (data_file == "LIST" || data_file.find(' ') != std::string::npos)
      fail("'{}': multi-file NRRD data ('data file: {}') is not supported", path, data_file);
    d.path = join_path(dirname_of(path), data_file);
    start = 0;
    file_size(d.path);  // names the missing data file
  }
  int64_t line_skip = has("line skip") ? parse_int(field("line skip"), path, "line skip") : 0;
  if (line_skip < 0) fail("'{}': malformed NRRD header: negative line skip", path);
  if (line_skip > 0) {
    std::FILE* f = std::fopen(d.path.c_str(), "rb");
    if (!f) fail("cannot open '{}': {}", d.path, std::strerror(errno));
    std::fseek(f, long(start), SEEK_SET);
    int ch;
    for (int64_t n = 0; n < line_skip && (ch = std::fgetc(f)) != EOF;)
      if (ch == '\n') ++n;
    start = uint64_t(std::ftell(f));
    std::fclose(f);
  }
  int64_t byte_skip = has("byte skip") ? parse_int(field("byte skip"), path, "byte skip") : 0;
  if (byte_skip < -1) fail("'{}': malformed NRRD header: byte skip {}", path, byte_skip);

  if (d.encoding == "gzip") {
    if (byte_skip == -1) fail("'{}': byte skip -1 is only allowed with raw encoding", path);
    d.gzip_start = start;
    d.offset = uint64_t(byte_skip);  // byte skip counts decompressed bytes for compressed encodings
  } else if (byte_skip == -1) {
    s.data_at_end = true;  // resolved once dims are validated
  } else {
    d.offset = start + uint64_t(byte_skip);
  }
}

}  // namespace

Source describe_nrrd(const std::string& path) {
  const Header h = read_header(path);
  const Fields field{h, path};
  Source s;
  s.origin = path;
  VolumeDesc& d = s.desc;
  d.dtype = parse_dtype(field("type"));
  read_axes(field, path, d);
  if (field.has("endian"))
    d.big_endian = parse_byte_order(field("endian"), "'" + path + "': malformed NRRD header: ", "endian");
  locate_data(field, path, s);
  return s;
}

}  // namespace vnr::detail
