# Source me: the MoveRL workspace and its venv in this shell (ROS tools need Debian's python first).
_moverl_root=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
export PATH="/usr/bin:$PATH"
# shellcheck disable=SC1091
source "$_moverl_root/devel/setup.bash"
# shellcheck disable=SC1091
source "$_moverl_root/.venv/bin/activate"
export ROS_HOSTNAME=127.0.0.1
export MOVERL_ROOT="$_moverl_root"
unset _moverl_root
