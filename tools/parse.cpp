#include "tools/parse.h"

#include <cctype>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <stdexcept>

#include "base/error.h"

namespace smr::tools {

std::uint64_t parse_bytes(const std::string& text, const std::string& option) {
  double v = 0.0;
  std::size_t used = 0;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  const std::string unit = text.substr(used);
  const int shift = unit.empty() || unit == "B"  ? 0
                    : unit == "K" || unit == "k" ? 10
                    : unit == "M" || unit == "m" ? 20
                    : unit == "G" || unit == "g" ? 30
                    : unit == "T" || unit == "t" ? 40
                                                 : -1;
  if (used == 0 || shift < 0 || !std::isfinite(v) || v <= 0.0 || v * std::ldexp(1.0, shift) > 1e18)
    throw_input(option + " expects a size such as 256M or 2G, got '" + text + "'");
  return static_cast<std::uint64_t>(v * std::ldexp(1.0, shift));
}

std::vector<double> parse_numbers(const std::string& text, std::size_t count,
                                  const std::string& option, const std::string& form) {
  std::vector<double> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      std::size_t used = 0;
      const double v = std::stod(item, &used);
      if (used != item.size() || !std::isfinite(v)) throw std::invalid_argument(item);
      out.push_back(v);
    } catch (const std::exception&) {
      throw_input(option + " expects " + form + ", got '" + text + "' ('" + item +
                  "' is not a finite number)");
    }
  }
  if (count == 0 ? out.empty() : out.size() != count)
    throw_input(option + " expects " + form + ", got '" + text + "'");
  return out;
}

std::pair<int, int> parse_viewport(const std::string& text, const std::string& option) {
  int w = 0, h = 0;
  char x = 0, extra = 0;
  std::stringstream vs(text);
  if (!(vs >> w >> x >> h) || x != 'x' || (vs >> extra))
    throw_input(option + " expects WxH (e.g. 1920x1080), got '" + text + "'");
  return {w, h};
}

std::string extension_of(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

}  // namespace smr::tools
