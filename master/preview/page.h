#pragma once
// The preview's one page (page.html, compiled in by CMake: nothing is read from disk at run time).

#include <string_view>

namespace raystack::master::preview {

std::string_view PageHtml();

}  // namespace raystack::master::preview
