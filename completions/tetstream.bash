# bash completion for tetstream. The subcommands, their options and the values of
# --dist and --format come from the installed binary's own --help, so they never fall
# out of date; containers (.tets) are offered where a subcommand reads one.

# Options that take no value (every other option's next word is its value).
_tetstream_flags=" --json -q --quiet -v --verbose --check --original-ids --points --binary --compress --voronoi-volume
  --neighbours --neighbors --resume --force --no-checkpoint --ascii --las-attributes --help -h --version "

# The values the help of `tetstream SUB` lists for OPTION: CLI11's {a,b,c} set when the
# option is checked against one, else the comma-separated words after the description's
# "Something:" up to its first full stop (parenthesised remarks dropped).
_tetstream_values() {
  local line set
  line=$("$1" $2 --help 2>/dev/null | grep -m1 -E -- "^ +(-[a-zA-Z], ?)?$3[ ,=]")
  [[ -z $line ]] && return
  set=$(printf '%s\n' "$line" | grep -o ':{[^}]*}' | head -1 | tr -d ':{}' | tr ',' ' ')
  if [[ -n $set ]]; then
    echo "$set"
    return
  fi
  printf '%s\n' "$line" | sed -E 's/\([^)]*\)//g; s/^ +-[^ ]+( [A-Z]+)?( \[[^]]*\])? +//; s/^[^:]*: //; s/\..*$//' |
    tr ',' '\n' | sed -E 's/^ +//; s/ +$//; s/^or //' | grep -E '^[a-z0-9][a-z0-9-]*$' | tr '\n' ' '
}

_tetstream() {
  local cur prev sub i words_help positional values
  COMPREPLY=()
  cur=${COMP_WORDS[COMP_CWORD]}
  prev=${COMP_WORDS[COMP_CWORD - 1]}
  sub=""
  for ((i = 1; i < COMP_CWORD; i++)); do
    case ${COMP_WORDS[i]} in
      --threads | --log-level | --json-file) ((i++)) ;;
      -*) ;;
      *) sub=${COMP_WORDS[i]}; break ;;
    esac
  done
  case $prev in
    --log-level) COMPREPLY=($(compgen -W "trace debug info warn error critical off" -- "$cur")); return ;;
    --threads) return ;;
    --dist | --format)
      values=$(_tetstream_values "${COMP_WORDS[0]}" "$sub" "$prev")
      if [[ -z $values ]]; then  # a binary whose help says nothing we can read
        case $prev in
          --dist) values="uniform ball ellipsoid-shell mixed clusters grid sphere terrain two-plates" ;;
          *) values="raw f32 f64 ply npy text las hdf5" ;;
        esac
      fi
      COMPREPLY=($(compgen -W "$values" -- "$cur"))
      return ;;
    --type) COMPREPLY=($(compgen -W "f32 f64" -- "$cur")); return ;;
    --byte-order) COMPREPLY=($(compgen -W "little big" -- "$cur")); return ;;
    --hull) COMPREPLY=($(compgen -W "nan open" -- "$cur")); return ;;
    --density) COMPREPLY=($(compgen -W "dtfe" -- "$cur")); return ;;
    --dtype) COMPREPLY=($(compgen -W "float64 float32" -- "$cur")); return ;;
    --index-dtype) COMPREPLY=($(compgen -W "auto int64" -- "$cur")); return ;;
  esac
  if [[ -z $sub && $cur != -* ]]; then
    words_help=$("${COMP_WORDS[0]}" --help 2>/dev/null |
      awk '/^Subcommands:/ { s = 1; next } /^[^ ]/ { s = 0 } s && /^  [a-z]/ { print $1 }')
    COMPREPLY=($(compgen -W "$words_help" -- "$cur"))
    return
  fi
  if [[ $cur == -* ]]; then
    words_help=$("${COMP_WORDS[0]}" $sub --help 2>/dev/null | grep -o -- '--[a-z0-9][a-z0-9-]*' | sort -u)
    COMPREPLY=($(compgen -W "$words_help --threads --log-level --json --json-file --quiet --verbose" -- "$cur"))
    return
  fi
  # The first positional word of a subcommand that reads a container: .tets files (and
  # directories on the way to them); anything else: any file.
  positional=0
  for ((i = i + 1; i < COMP_CWORD; i++)); do
    case ${COMP_WORDS[i]} in
      -*) [[ $_tetstream_flags == *" ${COMP_WORDS[i]} "* || ${COMP_WORDS[i]} == *=* ]] || ((i++)) ;;
      *) positional=$((positional + 1)) ;;
    esac
  done
  compopt -o filenames 2>/dev/null || true
  if [[ $positional == 0 && ($sub == cat || $sub == verify || $sub == field || $sub == convert) ]]; then
    COMPREPLY=($(compgen -f -X '!*.tets' -- "$cur"; compgen -d -- "$cur" || true))
    return
  fi
  COMPREPLY=($(compgen -f -- "$cur"))
}
complete -F _tetstream tetstream
