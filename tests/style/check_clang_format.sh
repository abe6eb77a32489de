#!/usr/bin/env bash
# Fails naming every tracked C++ source that the repository's .clang-format would change.
#   check_clang_format.sh SOURCE_DIR
# Exit 77 (CTest's skip) without clang-format 14 or a git checkout: the tree was formatted with
# version 14, and other versions lay out some constructs differently.
set -uo pipefail
root="$1"

formatter=""
for candidate in clang-format-14 clang-format; do
  if command -v "$candidate" >/dev/null 2>&1; then
    formatter="$candidate"
    break
  fi
done
if [ -z "$formatter" ]; then
  echo "clang-format not installed"
  exit 77
fi
version="$("$formatter" --version)"
if [[ ! "$version" =~ version\ 14\. ]]; then
  echo "clang-format 14 not installed (found: $version)"
  exit 77
fi
if ! listing="$(git -C "$root" ls-files -- '*.cpp' '*.cc' '*.h' '*.hpp' '*.cu' '*.cuh' 2>/dev/null)"; then
  echo "$root is not a git checkout: no list of tracked sources to check"
  exit 77
fi

# One clang-format process for every file (one per file costs most of the time); its messages
# ("file:line:col: error: code should be clang-formatted") name the files that differ.
files=()
while IFS= read -r file; do
  [ -f "$root/$file" ] && files+=("$file")  # skips a file deleted but not yet committed
done <<<"$listing"
checked=${#files[@]}
messages="$(cd "$root" && printf '%s\0' "${files[@]}" | xargs -0 "$formatter" --dry-run -Werror --style=file 2>&1)"
status=$?
mapfile -t unformatted < <(sed -n 's/^\(.*\):[0-9]*:[0-9]*: error: code should be clang-formatted.*/\1/p' <<<"$messages" | sort -u)
if ((status != 0 && ${#unformatted[@]} == 0)); then
  echo "$formatter failed without naming a file that differs:"
  echo "$messages"
  exit 1
fi

if ((${#unformatted[@]})); then
  echo "${#unformatted[@]} of $checked C++ sources differ from .clang-format ($formatter):"
  printf '  %s\n' "${unformatted[@]}"
  echo "fix with: clang-format -i ${unformatted[*]}"
  exit 1
fi
echo "$checked C++ sources match .clang-format ($formatter)"
