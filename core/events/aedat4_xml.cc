#include "core/events/aedat4_xml.h"

#include <cstdint>

namespace evloc::aedat4_xml {
namespace {

bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }

bool IsNameChar(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
         c == '-' || c == '.' || c == ':' || static_cast<unsigned char>(c) >= 0x80;
}

// Appends the UTF-8 encoding of `code`.
void AppendUtf8(uint32_t code, std::string* out) {
  if (code < 0x80) {
    out->push_back(static_cast<char>(code));
  } else if (code < 0x800) {
    out->push_back(static_cast<char>(0xc0 | (code >> 6)));
    out->push_back(static_cast<char>(0x80 | (code & 0x3f)));
  } else if (code < 0x10000) {
    out->push_back(static_cast<char>(0xe0 | (code >> 12)));
    out->push_back(static_cast<char>(0x80 | ((code >> 6) & 0x3f)));
    out->push_back(static_cast<char>(0x80 | (code & 0x3f)));
  } else {
    out->push_back(static_cast<char>(0xf0 | (code >> 18)));
    out->push_back(static_cast<char>(0x80 | ((code >> 12) & 0x3f)));
    out->push_back(static_cast<char>(0x80 | ((code >> 6) & 0x3f)));
    out->push_back(static_cast<char>(0x80 | (code & 0x3f)));
  }
}

class Parser {
 public:
  explicit Parser(const std::string& text) : text_(text) {}

  std::unique_ptr<Element> Document() {
    SkipMisc();
    if (!Peek('<')) Fail("expected the root element '<'");
    auto root = ParseElement(1);
    SkipMisc();
    if (position_ != text_.size()) Fail("expected the end of the document after the root element");
    return root;
  }

 private:
  [[noreturn]] void Fail(const std::string& what) const { throw XmlError{position_, what}; }
  bool Peek(char c) const { return position_ < text_.size() && text_[position_] == c; }
  bool StartsWith(const char* prefix) const {
    return text_.compare(position_, std::char_traits<char>::length(prefix), prefix) == 0;
  }
  void SkipSpace() {
    while (position_ < text_.size() && IsSpace(text_[position_])) ++position_;
  }
  // Skips up to and past `terminator`; fails naming `what` when it is missing.
  void SkipPast(const char* terminator, const char* what) {
    const size_t end = text_.find(terminator, position_);
    if (end == std::string::npos) Fail(std::string("expected the end of the ") + what);
    position_ = end + std::char_traits<char>::length(terminator);
  }
  // Whitespace, comments and processing instructions (the XML declaration) between elements.
  void SkipMisc() {
    for (;;) {
      SkipSpace();
      if (StartsWith("<!--")) {
        SkipPast("-->", "comment '-->'");
      } else if (StartsWith("<?")) {
        SkipPast("?>", "processing instruction '?>'");
      } else {
        return;
      }
    }
  }
  std::string Name(const char* what) {
    const size_t start = position_;
    while (position_ < text_.size() && IsNameChar(text_[position_])) ++position_;
    if (position_ == start) Fail(std::string("expected ") + what);
    return text_.substr(start, position_ - start);
  }
  // Decodes the entity at position_ ('&' ... ';') into `out`.
  void Entity(std::string* out) {
    const size_t end = text_.find(';', position_);
    if (end == std::string::npos || end - position_ > 12) Fail("expected an entity ending in ';'");
    const std::string name = text_.substr(position_ + 1, end - position_ - 1);
    if (name == "lt") {
      out->push_back('<');
    } else if (name == "gt") {
      out->push_back('>');
    } else if (name == "amp") {
      out->push_back('&');
    } else if (name == "quot") {
      out->push_back('"');
    } else if (name == "apos") {
      out->push_back('\'');
    } else if (name.size() >= 2 && name[0] == '#') {
      const bool hex = name[1] == 'x';
      uint32_t code = 0;
      const size_t first = hex ? 2 : 1;
      if (first >= name.size()) Fail("expected digits in a character reference");
      for (size_t i = first; i < name.size(); ++i) {
        const char c = name[i];
        uint32_t digit = 0;
        if (c >= '0' && c <= '9') {
          digit = static_cast<uint32_t>(c - '0');
        } else if (hex && c >= 'a' && c <= 'f') {
          digit = static_cast<uint32_t>(c - 'a' + 10);
        } else if (hex && c >= 'A' && c <= 'F') {
          digit = static_cast<uint32_t>(c - 'A' + 10);
        } else {
          Fail("expected a decimal or hexadecimal character reference");
        }
        code = code * (hex ? 16 : 10) + digit;
        if (code > 0x10ffff) Fail("expected a character reference below U+110000");
      }
      AppendUtf8(code, out);
    } else {
      Fail("unknown entity '&" + name + ";' (expected lt, gt, amp, quot, apos or &#N;)");
    }
    position_ = end + 1;
  }
  std::unique_ptr<Element> ParseElement(int depth) {
    if (depth > kMaxDepth) Fail("elements nested deeper than " + std::to_string(kMaxDepth));
    ++position_;  // '<'
    auto element = std::make_unique<Element>();
    element->name = Name("an element name");
    for (;;) {
      SkipSpace();
      if (StartsWith("/>")) {
        position_ += 2;
        return element;
      }
      if (Peek('>')) {
        ++position_;
        break;
      }
      std::string key = Name("an attribute name, '>' or '/>'");
      SkipSpace();
      if (!Peek('=')) Fail("expected '=' after attribute '" + key + "'");
      ++position_;
      SkipSpace();
      if (!Peek('"') && !Peek('\'')) Fail("expected a quoted value of attribute '" + key + "'");
      const char quote = text_[position_++];
      std::string value;
      for (;;) {
        if (position_ >= text_.size())
          Fail("expected the closing quote of attribute '" + key + "'");
        const char c = text_[position_];
        if (c == quote) break;
        if (c == '<') Fail("'<' inside the value of attribute '" + key + "'");
        if (c == '&') {
          Entity(&value);
        } else {
          value.push_back(c);
          ++position_;
        }
      }
      ++position_;
      element->attributes.emplace_back(std::move(key), std::move(value));
    }
    // Content: text, children, comments, CDATA, then the end tag.
    for (;;) {
      if (position_ >= text_.size()) Fail("expected the end tag '</" + element->name + ">'");
      const char c = text_[position_];
      if (c == '&') {
        Entity(&element->text);
      } else if (c != '<') {
        element->text.push_back(c);
        ++position_;
      } else if (StartsWith("</")) {
        const size_t tag_start = position_;
        position_ += 2;
        const std::string name = Name("an end tag name");
        if (name != element->name) {
          throw XmlError{tag_start, "expected the end tag '</" + element->name + ">', found '</" +
                                        name + ">'"};
        }
        SkipSpace();
        if (!Peek('>')) Fail("expected '>' closing the end tag");
        ++position_;
        return element;
      } else if (StartsWith("<!--")) {
        SkipPast("-->", "comment '-->'");
      } else if (StartsWith("<![CDATA[")) {
        const size_t start = position_ + 9;
        SkipPast("]]>", "CDATA section ']]>'");
        element->text.append(text_, start, position_ - 3 - start);
      } else if (StartsWith("<?")) {
        SkipPast("?>", "processing instruction '?>'");
      } else {
        element->children.push_back(ParseElement(depth + 1));
      }
    }
  }

  const std::string& text_;
  size_t position_ = 0;
};

}  // namespace

const std::string* Element::Attribute(const std::string& key) const {
  for (const auto& [name, value] : attributes) {
    if (name == key) return &value;
  }
  return nullptr;
}

const Element* Element::Child(const std::string& tag, const std::string& key,
                              const std::string& value) const {
  for (const auto& child : children) {
    if (child->name != tag) continue;
    const std::string* found = child->Attribute(key);
    if (found != nullptr && *found == value) return child.get();
  }
  return nullptr;
}

std::unique_ptr<Element> Parse(const std::string& text) { return Parser(text).Document(); }

}  // namespace evloc::aedat4_xml
