# bash completion for tetstream. The subcommands and their options come from the
# installed binary's own --help, so they never fall out of date.
_tetstream() {
  local cur prev sub i words_help
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
  COMPREPLY=($(compgen -f -- "$cur"))
  compopt -o filenames 2>/dev/null
}
complete -F _tetstream tetstream
