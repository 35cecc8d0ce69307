MODULE Weld
  ! A short weld seam on the table: approach, four seam points, retract.
  ! Programmed offline on the nominal model; tool and work object as taught on the cell.
  PERS tooldata gun:=[TRUE,[[30,0,210],[0.92388,0,0.382683,0]],[2.5,[0,0,80],[1,0,0,0],0,0,0]];
  TASK PERS wobjdata table:=[FALSE,TRUE,"",[[400,-100,50],[0.965926,0,0,0.258819]],[[0,0,10],[1,0,0,0]]];
  CONST jointtarget home:=[[0,0,0,0,30,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget approach:=[[40.00,-40.00,60.00],[0,0,0.996195,-0.087156],[-1,0,-2,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST robtarget seam{4}:=[[[50.00,-40.00,5.00],[0,0,0.996195,-0.087156],[-1,1,-2,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]],
      [[110.00,-40.00,5.00],[0,0,0.996195,-0.087156],[-1,1,-2,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]],
      [[150.00,-20.00,5.00],[0.015134,-0.172987,0.98106,-0.085832],[-1,0,-2,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]],
      [[170.00,20.00,5.00],[0.029809,-0.340719,0.936117,-0.0819],[-1,0,-2,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]]];

  PROC main()
    MoveAbsJ home\NoEOffs, v1000, z50, gun;
    MoveJ approach, v1000, z20, gun\WObj:=table;
    MoveL seam{1}, v100, fine, gun\WObj:=table;
    ! Arc on: SetDO doWeld, 1; (was MoveL [[50,-40,5],[0,0,0.996195,-0.087156],[-1,1,-2,0],[9E9,9E9,9E9,9E9,9E9,9E9]])
    MoveL seam{2}, v20, z1, gun\WObj:=table;
    MoveC seam{3}, seam{4}, v20, z1, gun\WObj:=table;
    MoveL Offs(seam{4},0,0,50), v200, z20, gun\WObj:=table;
    MoveL [[170.00,20.00,120.00],[0.029809,-0.340719,0.936117,-0.0819],[-1,0,-2,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]], v1000, z50, gun\WObj:=table;
    MoveAbsJ home\NoEOffs, v1000, fine, gun;
  ENDPROC
ENDMODULE
