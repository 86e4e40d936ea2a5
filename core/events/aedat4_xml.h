// The small XML subset of DV's stream descriptions (the AEDAT4 header's infoNode): elements with
// quoted attributes, character data with the five predefined entities and numeric character
// references, comments, an XML declaration, CDATA sections. Nothing else (no DTD, no
// namespaces). Internal to core/events (aedat4.cc) and its tests.
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace evloc::aedat4_xml {

// One element.
struct Element {
  // The tag name.
  std::string name;
  // The attributes in document order.
  std::vector<std::pair<std::string, std::string>> attributes;
  // The character data directly inside the element (entities decoded), concatenated.
  std::string text;
  // The child elements in document order.
  std::vector<std::unique_ptr<Element>> children;

  // The value of attribute `key`, or nullptr.
  const std::string* Attribute(const std::string& key) const;
  // The first child named `tag` whose attribute `key` is `value`, or nullptr.
  const Element* Child(const std::string& tag, const std::string& key,
                       const std::string& value) const;
};

// Thrown by Parse: what was expected at byte `offset` of the text.
struct XmlError {
  size_t offset = 0;
  std::string what;
};

// Deepest element nesting accepted.
inline constexpr int kMaxDepth = 64;

// Parses `text` into its root element. Throws XmlError.
std::unique_ptr<Element> Parse(const std::string& text);

}  // namespace evloc::aedat4_xml
