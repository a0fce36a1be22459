# Source me: the MoveRL workspace and its venv in this shell (ROS tools need Debian's python first).
_moverl_root=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
export PATH="/usr/bin:$PATH"
# A sourced script sees the positional parameters of whoever sources it, and catkin's setup.sh hands them to
# _setup_util.py (`./run.sh train --help` once printed only "setup.sh.XXXX: line 1: usage:: command not found").
# Sourced from a function called without arguments, it sees none.
_moverl_source() { source "$_moverl_root/devel/setup.bash"; }
_moverl_source
unset -f _moverl_source
# shellcheck disable=SC1091
source "$_moverl_root/.venv/bin/activate"
export ROS_HOSTNAME=127.0.0.1
export MOVERL_ROOT="$_moverl_root"
unset _moverl_root
